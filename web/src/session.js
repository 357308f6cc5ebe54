// The client's view of the server, no DOM: a Session applies the server's messages (JSON and
// binary scan lines) to a plain state object, of which the page is a view; `controlState` says
// what the operator may do now and why not; `describeRun` puts a push's outcome in words; the
// scene's particles and set point; the instrument behind the server. Runs in browsers and in
// Node (tests).
import { WS_VERSION, decodeScanLine, pushTolerance } from './wire.js';
import { formatPoint } from './format.js';
import { isSimulated, notOfferedWhy } from './words.js';
import * as assembly from './assembly.js';

/**
 * What a finished push means, in words: `ok`; `stopped` and who stopped it (a stop is not a
 * failure: the server's `failure` already starts "stopped: "); `missed` (it ended outside the
 * push's tolerance); else the failure code and reason; and the record (`record: false`: only a
 * missing one).
 */
export function describeRun(r, { record = true } = {}) {
  const rec0 = r.record ? `record ${r.record}` : r.record_error ? `no record: ${r.record_error}` : 'no record';
  // Without the record's name (the line under Stop: the Records list and the Events log name it);
  // a missing record is still said.
  const rec = record || !r.record ? ` (${rec0})` : '';
  if (r.outcome === 'ok') {
    const at = Array.isArray(r.estimate) ? `, particle now at ${formatPoint(r.estimate)}` : '';
    return `push of #${r.particle} ok${judgedText(r.judged)}${at}${rec}`;
  }
  const never = Array.isArray(r.estimate) ? `, particle left at ${formatPoint(r.estimate)}` : ', it never started';
  if (r.outcome === 'stopped' || r.outcome === 'missed') {
    const why = String(r.failure ?? 'no reason given').replace(/^stopped: /, '');
    return `push of #${r.particle} ${r.outcome}: ${why}${never}${rec}`;
  }
  return `push of #${r.particle} failed: ${r.outcome}: ${r.failure ?? 'no reason given'}${never}${rec}`;
}

/**
 * What the scan after the push measured (`run_done`'s `judged`), in words: the distance from
 * the target against the tolerance, and the corrections; '' for a run nobody judged.
 */
export function judgedText(j) {
  if (!j || !Number.isFinite(j.error_m) || !Number.isFinite(j.tolerance_m)) return '';
  const nm = (m) => `${(m * 1e9).toFixed(1)} nm`;
  const fixes = j.attempts > 1 ? `, after ${j.attempts - 1} correction${j.attempts > 2 ? 's' : ''}` : '';
  return `: measured ${nm(j.error_m)} from the target (tolerance ${nm(j.tolerance_m)})${fixes}`;
}

/**
 * A run's colour class: `good` (ok), `neutral` (stopped: somebody's decision, not a fault),
 * `warn` (missed: it ended outside the tolerance), `bad` (a failure).
 */
export function runClass(r) {
  return r.outcome === 'ok' ? 'good' : r.outcome === 'stopped' ? 'neutral' : r.outcome === 'missed' ? 'warn' : 'bad';
}

/**
 * The record of a push this page lost sight of (`lost`: the Session's `lostPush`, with the
 * server run it ran on and its run number), among /api/runs entries: the one that server run
 * wrote for that run, else null (a killed server writes none). Never matched by time or
 * particle alone: an earlier push of the same particle, or the next server's run of the same
 * number, is another push.
 */
export function lostPushRun(runs, lost) {
  if (!Array.isArray(runs) || !lost || lost.instance == null || lost.run == null) return null;
  return runs.find((x) => x.instance === lost.instance && x.run === lost.run && x.particle === lost.particle) ?? null;
}

/**
 * The strategy's contact set point as a tip force (N), from an /api/scene document: the set
 * point reading `ζ_set` (V) is a deflection (`set_point_v` − `baseline_v`) / `gain_v_per_nm`,
 * and the force `k_z ζ` (positive repulsive, as telemetry's `tip_force_n`). Null when the scene
 * lacks a value.
 */
export function setPointForceN(scene) {
  const v = scene?.strategy?.set_point_v;
  const b = scene?.sensor?.baseline_v;
  const g = scene?.sensor?.gain_v_per_nm;
  const k = scene?.cantilever?.stiffness_n_per_m;
  if (![v, b, g, k].every(Number.isFinite) || g === 0) return null;
  return k * ((v - b) / g) * 1e-9;
}

/** Particles of an /api/scene document, in metres: [{id, radius, x, y, material}]. */
export function sceneParticles(scene) {
  const ps = (scene && Array.isArray(scene.particles)) ? scene.particles : [];
  return ps.map((p) => ({
    id: p.id,
    material: p.material ?? '',
    radius: (p.radius_nm ?? 0) / 1e9,
    x: (p.x_um ?? 0) / 1e6,
    y: (p.y_um ?? 0) / 1e6,
  }));
}

/** What the page can do with the simulated AFM: everything (`welcome`'s `instrument.offers`). */
export const OFFERS = Object.freeze(['push', 'scan', 'assemble', 'haptic']);

/**
 * The instrument behind the server, from its `welcome`: {backend, feed_rate_hz, z_closed_locally,
 * read_only, offers}. A server older than `instrument` runs the simulated AFM at its tick rate
 * and offers everything; a real controller offers only what it lists.
 */
export function welcomeInstrument(m) {
  const i = m.instrument;
  if (!i || typeof i !== 'object') {
    return { backend: 'simulated AFM', feed_rate_hz: Number.isFinite(m.tick_hz) ? m.tick_hz : null, z_closed_locally: false, read_only: false, offers: [...OFFERS] };
  }
  return {
    backend: typeof i.backend === 'string' && i.backend ? i.backend : 'unnamed instrument',
    feed_rate_hz: Number.isFinite(i.feed_rate_hz) && i.feed_rate_hz > 0 ? i.feed_rate_hz : null,
    z_closed_locally: !!i.z_closed_locally,
    read_only: !!i.read_only,
    offers: Array.isArray(i.offers) ? i.offers.filter((o) => typeof o === 'string') : [],
  };
}

// ---------------------------------------------------------------------------------------------
// Session: the client's view of the server.

const LOG_MAX = 50;
const RUNS_MAX = 20;
const COMMANDS_MAX = 200;

/** A fresh state. */
export function initialState({ traceSeconds = 10 } = {}) {
  return {
    connection: 'idle', // idle | connecting | open | closed
    reconnect: null, // {attempt, delayMs} while waiting to reconnect
    version: null,
    client: null,
    role: null, // viewer | operator
    scene: null,
    tickHz: null,
    instrument: null, // the instrument behind the server (welcome: welcomeInstrument), kept while disconnected
    pushTolerance: null, // a push's tolerance as the server checks it (welcome): {default, min, max} nm
    lease: null, // holder's client id
    leaseName: null, // the holder's name (their token's), when the server said
    name: null, // this connection's person, as the server named them
    phase: null,
    tip: null, // last telemetry {t, stage:[x,y,z] m, volts, phase, estimate}
    telemetryCount: 0,
    trace: { seconds: traceSeconds, t: [], volts: [], z: [], force: [] },
    serverParticles: null, // particle positions the server sent (state), kept over scene reloads
    push: null, // the push running: {particle, path: [[x, y] m…], by}
    scanStale: false, // a push has run since the scan shown
    lastRun: null, // the newest run_done
    leaseNote: null, // why the lease changed, when the server said
    stateReceived: false, // the server's `state` arrived on this connection
    lagged: { events: 0, skipped: 0 },
    scan: null, // {id, xres, yres, x_offset, y_offset, x_real, y_real, heights, received, lines, min, max, done, record, previousRun, interrupted}
    strayLines: 0, // scan lines of no current scan
    runs: [], // run_done messages, newest last
    errors: [], // {at, id, code, message, command}
    lastError: null,
    commands: new Map(), // id → {id, type, msg, status: pending|ok|error, code, message}
    nextId: 1,
    particles: [], // from /api/scene, metres; moved by run_done estimates
    stageRange: 100e-6,
    pushSpeed: null, // the scene's push speed (m/s), for a push's time left
    shutdown: null,
    instance: null, // the server's instance id (welcome): another one on a reconnect is a restart
    startedUnixMs: null, // when that server started
    restarted: false, // the last welcome came from another instance than the one before
    lostPush: null, // the push that ran when the connection closed: its end was not seen
    assembly: null, // the assembly running or last seen (src/assembly.js)
  };
}

/**
 * The server's JSON messages (proto/README.md), one handler per `type`: `handlers[type](session,
 * msg)` changes the store (`session.state`) and returns what changed, as an event {kind, ...}
 * from which the page marks the views to redraw. A new message is one more entry.
 */
const handlers = {
  welcome(session, m) {
    const s = session.state;
    s.version = m.version;
    s.client = m.client;
    s.role = m.role;
    s.name = m.name ?? null;
    s.lease = m.lease ?? null;
    s.leaseName = m.lease_name ?? null;
    s.scene = m.scene;
    s.tickHz = m.tick_hz;
    s.instrument = welcomeInstrument(m);
    // A real controller's sample is not the scene's: no particle is drawn until one is found.
    if (!isSimulated(s.instrument)) s.particles = [];
    s.pushTolerance = pushTolerance(m);
    s.stateReceived = false;
    if (m.version !== WS_VERSION) {
      session.logError('version', `the server speaks protocol ${m.version}, this page ${WS_VERSION}`);
    }
    const previous = s.instance;
    const instance = m.instance ?? null;
    s.restarted = previous !== null && instance !== null && instance !== previous;
    s.instance = instance;
    if (s.restarted && s.scan) {
      // The previous run's scan: one it never finished never will be, and the restarted
      // server's sample (the scene's) is not what it shows. Its scan ids start again.
      s.scan.previousRun = true;
      s.scan.interrupted = !s.scan.done;
      s.scanStale = true;
    }
    s.startedUnixMs = m.started_unix_ms ?? null;
    return { kind: 'welcome', restarted: s.restarted, previous };
  },

  state(session, m) {
    const s = session.state;
    s.stateReceived = true;
    s.lease = m.lease ?? null;
    s.leaseName = m.lease_name ?? null;
    s.phase = m.phase ?? null;
    if (Array.isArray(m.stage)) s.tip = { t: null, stage: m.stage, volts: 0, phase: m.phase, estimate: null, force: 0 };
    for (const q of m.particles ?? []) {
      const p = s.particles.find((pp) => pp.id === q.id);
      if (p) {
        p.x = q.x;
        p.y = q.y;
        p.radius = q.radius;
      } else {
        s.particles.push({ id: q.id, material: '', radius: q.radius, x: q.x, y: q.y });
      }
    }
    s.serverParticles = (m.particles ?? []).map((q) => ({ ...q }));
    s.push = m.push ? { ...m.push } : null;
    const sc = m.scan ?? null;
    let scanChanged = false;
    let scanFinished = false;
    if (sc && (!s.scan || s.scan.id !== sc.scan || s.scan.previousRun)) {
      session.startScan({ ...sc, type: 'scan_start' });
      s.scan.done = !!sc.done;
      s.scan.record = sc.record ?? null;
      scanChanged = true;
    } else if (sc && sc.done && !s.scan.done) {
      // The scan shown ended while this page was away: done, and its record has the lines
      // this page missed.
      s.scan.done = true;
      s.scan.record = sc.record ?? null;
      scanFinished = true;
    }
    s.scanStale = sc ? !!sc.stale : !!s.scan?.previousRun;
    const assemblyChanged = assembly.fromState(s, m.assembly ?? null);
    return { kind: 'state', scan: sc, scanChanged, scanFinished, assemblyChanged };
  },

  push_started(session, m) {
    const s = session.state;
    s.push = {
      particle: m.particle, path: m.path ?? [], by: m.by ?? null, run: m.run ?? null,
      attempt: m.attempt ?? 1, warnings: m.warnings ?? [], strategy: m.strategy ?? null,
    };
    return { kind: 'push_started', push: s.push };
  },

  ok(session, m) {
    const c = m.id != null ? session.state.commands.get(m.id) : undefined;
    if (c) {
      c.status = 'ok';
      c.code = null;
      c.message = null;
    }
    return { kind: 'reply', ok: true, id: m.id ?? null, command: c ?? null };
  },

  error(session, m) {
    const c = m.id != null ? session.state.commands.get(m.id) : undefined;
    if (c) {
      c.status = 'error';
      c.code = m.code;
      c.message = m.message;
    }
    session.logError(m.code, m.message, m.id);
    return { kind: 'reply', ok: false, id: m.id ?? null, command: c ?? null };
  },

  telemetry(session, m) {
    const s = session.state;
    const force = Number.isFinite(m.tip_force_n) ? m.tip_force_n : 0;
    s.tip = { t: m.t, seq: Number.isSafeInteger(m.seq) ? m.seq : null, stage: m.stage, volts: m.volts, phase: m.phase, estimate: m.estimate ?? null, force, haptic: m.haptic ?? null };
    s.phase = m.phase;
    s.telemetryCount++;
    const tr = s.trace;
    // A server restart starts its clock again: drop a trace that ran ahead.
    if (tr.t.length && m.t < tr.t[tr.t.length - 1]) {
      tr.t.length = 0;
      tr.volts.length = 0;
      tr.z.length = 0;
      tr.force.length = 0;
    }
    tr.t.push(m.t);
    tr.volts.push(m.volts);
    tr.z.push(m.stage[2]);
    tr.force.push(force);
    let drop = 0;
    while (drop < tr.t.length && tr.t[drop] < m.t - tr.seconds) drop++;
    if (drop) {
      tr.t.splice(0, drop);
      tr.volts.splice(0, drop);
      tr.z.splice(0, drop);
      tr.force.splice(0, drop);
    }
    return { kind: 'telemetry' };
  },

  lagged(session, m) {
    const s = session.state;
    s.lagged.events++;
    s.lagged.skipped += m.skipped ?? 0;
    return { kind: 'lagged' };
  },

  lease(session, m) {
    const s = session.state;
    const before = s.lease;
    const hadIt = before !== null && before === s.client;
    s.lease = m.holder ?? null;
    s.leaseName = m.holder_name ?? null;
    s.leaseNote = m.reason ?? null;
    const lost = hadIt && s.lease !== s.client;
    return { kind: 'lease', before, lost, reason: m.reason ?? null };
  },

  run_done(session, m) {
    const s = session.state;
    s.lastRun = m;
    s.push = null;
    if (Array.isArray(m.estimate)) s.scanStale = s.scan !== null;
    s.runs.push(m);
    if (s.runs.length > RUNS_MAX) s.runs.splice(0, s.runs.length - RUNS_MAX);
    const p = s.particles.find((q) => q.id === m.particle);
    if (p && Array.isArray(m.estimate)) {
      p.x = m.estimate[0];
      p.y = m.estimate[1];
    }
    const q = (s.serverParticles ?? []).find((qq) => qq.id === m.particle);
    if (q && Array.isArray(m.estimate)) {
      q.x = m.estimate[0];
      q.y = m.estimate[1];
    }
    return { kind: 'run_done', run: m };
  },

  assembly_planned: (session, m) => assembly.planned(session.state, m),
  assembly_move_started: (session, m) => assembly.moveStarted(session.state, m),
  assembly_move_ended: (session, m) => assembly.moveEnded(session.state, m),
  assembly_site_filled: (session, m) => assembly.siteFilled(session.state, m),
  assembly_replanned: (session, m) => assembly.replanned(session.state, m),
  assembly_done: (session, m) => assembly.done(session.state, m),

  scan_start(session, m) {
    if (!session.startScan(m)) return { kind: 'error' };
    return { kind: 'scan_start' };
  },

  scan_done(session, m) {
    const s = session.state;
    if (s.scan && s.scan.id === m.scan) {
      s.scan.done = true;
      s.scan.record = m.record ?? null;
    }
    return { kind: 'scan_done', record: m.record ?? null, record_error: m.record_error ?? null };
  },

  shutdown(session, m) {
    session.state.shutdown = m.reason ?? '';
    return { kind: 'shutdown' };
  },
};

export class Session {
  constructor(opts) {
    this.state = initialState(opts);
  }

  /** Loads an /api/scene document: the particles and the stage range. */
  setScene(scene) {
    const inst = this.state.instrument;
    this.state.particles = inst && !isSimulated(inst) ? [] : sceneParticles(scene);
    // The server's word (state, then run_done) beats the scene file's positions, whichever
    // arrived first.
    for (const q of this.state.serverParticles ?? []) {
      const p = this.state.particles.find((pp) => pp.id === q.id);
      if (p) {
        p.x = q.x;
        p.y = q.y;
      }
    }
    const r = scene?.stage?.range_um;
    if (typeof r === 'number' && r > 0) this.state.stageRange = r / 1e6;
    const v = scene?.push?.speed_um_per_s;
    this.state.pushSpeed = Number.isFinite(v) && v > 0 ? v / 1e6 : null;
    return this.state;
  }

  /** Connection events: `connecting`, `open`, `closed` (with the attempt about to follow). */
  connecting() {
    this.state.connection = 'connecting';
    this.state.reconnect = null;
  }

  opened() {
    this.state.connection = 'open';
    this.state.reconnect = null;
    this.state.shutdown = null;
  }

  closed(attempt, delayMs) {
    const s = this.state;
    s.connection = 'closed';
    s.reconnect = attempt ? { attempt, delayMs } : null;
    // What the server told this connection no longer holds.
    s.client = null;
    s.role = null;
    s.lease = null;
    s.phase = null;
    if (s.push) s.lostPush = { ...s.push, instance: s.instance };
    s.push = null;
    s.stateReceived = false;
    for (const c of s.commands.values()) {
      if (c.status === 'pending') {
        c.status = 'error';
        c.code = 'disconnected';
        c.message = 'the connection closed before a reply';
      }
    }
  }

  /** Records an outgoing command and gives it an id; returns the message to send. */
  issue(msg) {
    const s = this.state;
    const id = s.nextId;
    s.nextId = id >= 0xffffffff ? 1 : id + 1;
    const m = { ...msg, id };
    s.commands.set(id, { id, type: msg.type, msg: m, status: 'pending', code: null, message: null });
    if (s.commands.size > COMMANDS_MAX) s.commands.delete(s.commands.keys().next().value);
    return m;
  }

  /** Whether this client holds the lease. */
  get hasLease() {
    const s = this.state;
    return s.client !== null && s.lease === s.client;
  }

  logError(code, message, id = null) {
    const s = this.state;
    const cmd = id !== null && id !== undefined ? s.commands.get(id) : undefined;
    const e = { at: Date.now(), id: id ?? null, code, message, command: cmd ? cmd.type : null };
    s.errors.push(e);
    if (s.errors.length > LOG_MAX) s.errors.splice(0, s.errors.length - LOG_MAX);
    s.lastError = e;
    return e;
  }

  /**
   * Applies one server message: a parsed object, JSON text, or a binary scan-line frame
   * (ArrayBuffer / typed array). Returns what changed, as a small event object the view can
   * use to update only what it must: {kind, ...}.
   */
  apply(msg) {
    if (typeof msg === 'string') {
      try {
        msg = JSON.parse(msg);
      } catch (e) {
        this.logError('client_parse', `a text frame is not JSON: ${e.message}`);
        return { kind: 'error' };
      }
    } else if (msg instanceof ArrayBuffer || ArrayBuffer.isView(msg)) {
      return this.applyScanLine(msg);
    }
    if (!msg || typeof msg !== 'object' || typeof msg.type !== 'string') {
      this.logError('client_parse', 'a server message without a type');
      return { kind: 'error' };
    }
    // Own keys only: a type named like an Object method (`toString`) is no message either.
    if (!Object.hasOwn(handlers, msg.type)) return { kind: 'unknown', type: msg.type };
    return handlers[msg.type](this, msg);
  }

  /** A new, empty scan (from `scan_start`, `state` or a record); false when its size is absurd. */
  startScan(msg) {
    const s = this.state;
    const n = msg.xres * msg.yres;
    if (!Number.isInteger(n) || n <= 0 || n > 512 * 512) {
      this.logError('client_scan', `scan_start with ${msg.xres}×${msg.yres} pixels`);
      s.scan = null;
      return false;
    }
    s.scanStale = false;
    s.scan = {
      id: msg.scan,
      xres: msg.xres,
      yres: msg.yres,
      x_offset: msg.x_offset,
      y_offset: msg.y_offset,
      x_real: msg.x_real,
      y_real: msg.y_real,
      heights: new Float32Array(n), // row-major, row 0 = line 0 = lowest y
      received: new Uint8Array(msg.yres),
      lines: 0,
      min: Infinity,
      max: -Infinity,
      done: false,
      record: null,
      previousRun: false, // shown from before a server restart
      interrupted: false, // that server never finished it
      version: 0, // bumped by every change of the heights
    };
    return true;
  }

  /**
   * Fills the current scan `scanId` with a whole image (a parsed GSF record: `heights`
   * row-major, first row lowest y). Returns false when it is not the scan shown or does not fit.
   */
  fillScan(scanId, heights) {
    const sc = this.state.scan;
    if (!sc || sc.id !== scanId || heights.length !== sc.xres * sc.yres) return false;
    sc.heights.set(heights);
    sc.received.fill(1);
    sc.lines = sc.yres;
    sc.min = Infinity;
    sc.max = -Infinity;
    for (const h of heights) {
      if (Number.isFinite(h)) {
        if (h < sc.min) sc.min = h;
        if (h > sc.max) sc.max = h;
      }
    }
    sc.done = true;
    sc.version++;
    return true;
  }

  applyScanLine(buf) {
    const s = this.state;
    let f;
    try {
      f = decodeScanLine(buf);
    } catch (e) {
      this.logError('client_frame', e.message);
      return { kind: 'error' };
    }
    const sc = s.scan;
    if (!sc || sc.id !== f.scan) {
      s.strayLines++;
      return { kind: 'stray_line' };
    }
    if (f.xres !== sc.xres || f.yres !== sc.yres || f.line >= sc.yres) {
      this.logError('client_frame', `scan ${f.scan} line ${f.line}: ${f.xres}×${f.yres} does not fit the scan's ${sc.xres}×${sc.yres}`);
      return { kind: 'error' };
    }
    sc.heights.set(f.heights, f.line * sc.xres);
    sc.version++;
    if (!sc.received[f.line]) {
      sc.received[f.line] = 1;
      sc.lines++;
    }
    for (const h of f.heights) {
      if (Number.isFinite(h)) {
        if (h < sc.min) sc.min = h;
        if (h > sc.max) sc.max = h;
      }
    }
    return { kind: 'scan_line', line: f.line, y: f.y };
  }
}

/** The lease holder by name and client (`alice (client 3)`), or `client 3` when unnamed. */
export function holderText(state) {
  return state.leaseName ? `${state.leaseName} (client ${state.lease})` : `client ${state.lease}`;
}

/**
 * What each operator control may do now, and why not: {enabled, why} per control. Viewers, a
 * closed connection, what the instrument does not offer, then commands that need the lease are
 * explained in words (tooltips): the lease would not help what the instrument does not offer.
 */
export function controlState(state) {
  const open = state.connection === 'open' && state.client !== null;
  const operator = state.role === 'operator';
  const mine = open && state.lease !== null && state.lease === state.client;
  const no = (why) => ({ enabled: false, why });
  // A tooltip's sentence begins with its capital: `Client 9`, or the holder's name as written.
  const holder = state.leaseName ? holderText(state) : `Client ${state.lease}`;
  const yes = { enabled: true, why: '' };
  let base = null;
  if (!open) base = 'Not connected to the server';
  else if (!operator) base = 'Viewer connection: open the page with the operator token (?token=…) to command';
  const needLease = base ? no(base) : mine ? yes : state.lease === null ? no('Take the lease first') : no(`${holder} holds the lease`);
  const offered = (what, s) => {
    const why = base ? '' : notOfferedWhy(state.instrument, what);
    return why ? no(why) : s;
  };
  const link = state.tip?.haptic?.link ?? null;
  return {
    hapticEngage: offered('haptic', !needLease.enabled ? needLease : link === 'up' ? yes : no(`The haptic link is ${link ?? 'not reported'}: engage once it is up`)),
    takeLease: base ? no(base) : mine ? no('You hold the lease') : state.lease !== null ? no(`${holder} holds the lease`) : yes,
    releaseLease: base ? no(base) : mine ? yes : no('You do not hold the lease'),
    push: offered('push', needLease),
    scan: offered('scan', needLease),
    assemble: offered('assemble', needLease),
    haptic: offered('haptic', needLease),
    stop: needLease,
  };
}
