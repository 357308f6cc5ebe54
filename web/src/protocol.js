// The nanopush WebSocket protocol (proto/README.md, proto/src/ws.rs) for the browser, with no
// DOM: the binary scan-line decoder, builders of the client's JSON messages, and a Session
// that applies the server's messages to a plain state object (the page is a view of it).
// Runs in browsers and in Node (tests).

/** `ws::WS_VERSION`: the protocol version this client speaks. */
export const WS_VERSION = 1;
/** Magic of a scan-line frame. */
export const SCAN_LINE_MAGIC = 'NPSL';
/** Header length of a scan-line frame (bytes). */
export const SCAN_LINE_HEADER_LEN = 32;
/** Streams a client can subscribe to. */
export const STREAMS = Object.freeze(['tip', 'scan']);

/** A binary frame that is not a valid scan line. `reason` is `short`, `magic` or `version`. */
export class FrameError extends Error {
  constructor(reason, message) {
    super(message);
    this.name = 'FrameError';
    this.reason = reason;
  }
}

function toDataView(buf) {
  if (buf instanceof ArrayBuffer) return new DataView(buf);
  if (ArrayBuffer.isView(buf)) return new DataView(buf.buffer, buf.byteOffset, buf.byteLength);
  throw new TypeError('decodeScanLine: expected an ArrayBuffer or a typed array');
}

/**
 * Decodes one binary scan-line frame (little-endian): magic `NPSL`, u16 version (1), u16
 * reserved, u32 scan, u32 line, u32 xres, u32 yres, f64 line y (m), then xres f32 heights (m).
 * Throws a FrameError on a short frame, a bad magic, an unknown version or a length that does
 * not match xres, as `ScanLineHeader::decode` does.
 * @returns {{scan:number, line:number, xres:number, yres:number, y:number, heights:Float32Array}}
 */
export function decodeScanLine(buf) {
  const v = toDataView(buf);
  if (v.byteLength < SCAN_LINE_HEADER_LEN) {
    throw new FrameError('short', `scan line: ${v.byteLength} bytes, shorter than the ${SCAN_LINE_HEADER_LEN}-byte header`);
  }
  const magic = String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3));
  if (magic !== SCAN_LINE_MAGIC) {
    throw new FrameError('magic', `scan line: bad magic ${JSON.stringify(magic)} (expected "NPSL")`);
  }
  const version = v.getUint16(4, true);
  if (version !== 1) {
    throw new FrameError('version', `scan line: version ${version}, this client reads version 1`);
  }
  const scan = v.getUint32(8, true);
  const line = v.getUint32(12, true);
  const xres = v.getUint32(16, true);
  const yres = v.getUint32(20, true);
  const y = v.getFloat64(24, true);
  const need = SCAN_LINE_HEADER_LEN + 4 * xres;
  if (v.byteLength !== need) {
    throw new FrameError('short', `scan line: ${v.byteLength} bytes, xres ${xres} needs ${need}`);
  }
  const heights = new Float32Array(xres);
  for (let i = 0; i < xres; i++) heights[i] = v.getFloat32(SCAN_LINE_HEADER_LEN + 4 * i, true);
  return { scan, line, xres, yres, y, heights };
}

/** Encodes a scan line as the Rust encoder does (for tests and demos). */
export function encodeScanLine({ scan, line, xres, yres, y }, heights) {
  const b = new ArrayBuffer(SCAN_LINE_HEADER_LEN + 4 * heights.length);
  const v = new DataView(b);
  for (let i = 0; i < 4; i++) v.setUint8(i, SCAN_LINE_MAGIC.charCodeAt(i));
  v.setUint16(4, 1, true);
  v.setUint16(6, 0, true);
  v.setUint32(8, scan, true);
  v.setUint32(12, line, true);
  v.setUint32(16, xres, true);
  v.setUint32(20, yres, true);
  v.setFloat64(24, y, true);
  heights.forEach((h, i) => v.setFloat32(SCAN_LINE_HEADER_LEN + 4 * i, h, true));
  return b;
}

// ---------------------------------------------------------------------------------------------
// Client → server messages. Each builder returns a plain object with only the documented
// fields (the server refuses unknown ones) and checks the documented ranges first, throwing a
// RangeError that names the field, so the operator hears about a typo before a round trip.

function finite(name, x) {
  if (typeof x !== 'number' || !Number.isFinite(x)) throw new RangeError(`${name} must be a finite number, got ${x}`);
  return x;
}

function withId(msg, id) {
  if (id !== undefined && id !== null) {
    if (!Number.isInteger(id) || id < 0 || id > 0xffffffff) throw new RangeError(`id must be a u32, got ${id}`);
    msg.id = id;
  }
  return msg;
}

function particleId(p) {
  if (!Number.isInteger(p) || p < 0 || p > 0xffffffff) throw new RangeError(`particle must be a particle id (u32), got ${p}`);
  return p;
}

export const commands = {
  subscribe(streams = STREAMS, id) {
    for (const s of streams) if (!STREAMS.includes(s)) throw new RangeError(`streams: unknown stream ${JSON.stringify(s)} (tip, scan)`);
    return withId({ type: 'subscribe', streams: [...streams] }, id);
  },
  takeLease(id) {
    return withId({ type: 'take_lease' }, id);
  },
  releaseLease(id) {
    return withId({ type: 'release_lease' }, id);
  },
  /** Push `particle` by `distanceUm` (0, 100] along `directionDeg` [-360, 360] (from +x). */
  pushBy(particle, distanceUm, directionDeg, id) {
    finite('distance_um', distanceUm);
    finite('direction_deg', directionDeg);
    if (!(distanceUm > 0 && distanceUm <= 100)) throw new RangeError(`distance_um must be in (0, 100] µm, got ${distanceUm}`);
    if (!(directionDeg >= -360 && directionDeg <= 360)) throw new RangeError(`direction_deg must be in [-360, 360], got ${directionDeg}`);
    return withId({ type: 'push', particle: particleId(particle), distance_um: distanceUm, direction_deg: directionDeg }, id);
  },
  /** Push `particle` to the target (µm) in [0, rangeUm]². */
  pushTo(particle, xUm, yUm, id, rangeUm = 100) {
    finite('to_x_um', xUm);
    finite('to_y_um', yUm);
    if (!(xUm >= 0 && xUm <= rangeUm)) throw new RangeError(`to_x_um must be in [0, ${rangeUm}] µm, got ${xUm}`);
    if (!(yUm >= 0 && yUm <= rangeUm)) throw new RangeError(`to_y_um must be in [0, ${rangeUm}] µm, got ${yUm}`);
    return withId({ type: 'push', particle: particleId(particle), to_x_um: xUm, to_y_um: yUm }, id);
  },
  /** A scan; any of centreXUm, centreYUm, sizeUm (0, 100], pixels [8, 512] may be left out. */
  scan({ centreXUm, centreYUm, sizeUm, pixels } = {}, id) {
    const m = { type: 'scan' };
    if (centreXUm !== undefined && centreXUm !== null) m.centre_x_um = finite('centre_x_um', centreXUm);
    if (centreYUm !== undefined && centreYUm !== null) m.centre_y_um = finite('centre_y_um', centreYUm);
    if (sizeUm !== undefined && sizeUm !== null) {
      finite('size_um', sizeUm);
      if (!(sizeUm > 0 && sizeUm <= 100)) throw new RangeError(`size_um must be in (0, 100] µm, got ${sizeUm}`);
      m.size_um = sizeUm;
    }
    if (pixels !== undefined && pixels !== null) {
      if (!Number.isInteger(pixels) || pixels < 8 || pixels > 512) throw new RangeError(`pixels must be an integer in [8, 512], got ${pixels}`);
      m.pixels = pixels;
    }
    return withId(m, id);
  },
  stop(id) {
    return withId({ type: 'stop' }, id);
  },
  /**
   * A haptic z-control command: `engage`, `release`, `recenter`, or `scale` with `nmPerMm`
   * [0.01, 1000] and/or `pullOffAtHandN` [0.01, 10].
   */
  haptic(action, { nmPerMm, pullOffAtHandN } = {}, id) {
    if (!['engage', 'release', 'recenter', 'scale'].includes(action)) throw new RangeError(`action must be engage, release, recenter or scale, got ${JSON.stringify(action)}`);
    const m = { type: 'haptic', action };
    if (action === 'scale') {
      if (nmPerMm === undefined && pullOffAtHandN === undefined) throw new RangeError('scale needs nm_per_mm and/or pull_off_at_hand_n');
      if (nmPerMm !== undefined) {
        finite('nm_per_mm', nmPerMm);
        if (!(nmPerMm >= 0.01 && nmPerMm <= 1000)) throw new RangeError(`nm_per_mm must be in [0.01, 1000] nm/mm, got ${nmPerMm}`);
        m.nm_per_mm = nmPerMm;
      }
      if (pullOffAtHandN !== undefined) {
        finite('pull_off_at_hand_n', pullOffAtHandN);
        if (!(pullOffAtHandN >= 0.01 && pullOffAtHandN <= 10)) throw new RangeError(`pull_off_at_hand_n must be in [0.01, 10] N, got ${pullOffAtHandN}`);
        m.pull_off_at_hand_n = pullOffAtHandN;
      }
    }
    return withId(m, id);
  },
  ping(id) {
    return withId({ type: 'ping' }, id);
  },
};

/** The JSON text of a client message. */
export function encodeCommand(msg) {
  if (!msg || typeof msg.type !== 'string') throw new TypeError('encodeCommand: a message needs a type');
  return JSON.stringify(msg);
}

/**
 * The WebSocket URL for a page location: same host, `/ws`, with the page's `token` query
 * parameter passed on (none → a viewer connection).
 */
export function wsUrl(loc) {
  const proto = loc.protocol === 'https:' ? 'wss:' : 'ws:';
  const token = new URLSearchParams(loc.search || '').get('token');
  return `${proto}//${loc.host}/ws` + (token ? `?token=${encodeURIComponent(token)}` : '');
}

/** An HTTP API path with the page's `?token=` passed on (a server with a viewer token needs it). */
export function apiUrl(path, loc) {
  const token = new URLSearchParams(loc.search || '').get('token');
  if (!token) return path;
  return path + (path.includes('?') ? '&' : '?') + `token=${encodeURIComponent(token)}`;
}

/** Reconnect delay (ms) for the n-th attempt (1-based): 0.5 s doubling to 15 s at most. */
export function backoffMs(attempt, baseMs = 500, maxMs = 15000) {
  const n = Math.max(1, attempt);
  return Math.min(maxMs, baseMs * 2 ** (n - 1));
}

/**
 * Parses a Gwyddion Simple Field (the scan records of `/api/records/NAME.gsf`): the header's
 * `Key = Value` lines, NUL padding to a multiple of 4, then XRes×YRes little-endian f32
 * (row-major, first row = lowest y, as `nanopush` writes it). Throws an Error naming what is wrong.
 * @returns {{xres:number, yres:number, x_real:number, y_real:number, x_offset:number, y_offset:number, title:string, heights:Float32Array}}
 */
export function parseGsf(buf) {
  const bytes = buf instanceof ArrayBuffer ? new Uint8Array(buf) : new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
  const magic = 'Gwyddion Simple Field 1.0\n';
  const head = String.fromCharCode(...bytes.subarray(0, magic.length));
  if (head !== magic) throw new Error('GSF: not a Gwyddion Simple Field (bad first line)');
  const nul = bytes.indexOf(0);
  if (nul < 0) throw new Error('GSF: no NUL after the header');
  const text = new TextDecoder().decode(bytes.subarray(magic.length, nul));
  const kv = {};
  for (const line of text.split('\n')) {
    const i = line.indexOf('=');
    if (i > 0) kv[line.slice(0, i).trim()] = line.slice(i + 1).trim();
  }
  const xres = Number(kv.XRes);
  const yres = Number(kv.YRes);
  if (!Number.isInteger(xres) || !Number.isInteger(yres) || xres < 1 || yres < 1 || xres * yres > 4096 * 4096) {
    throw new Error(`GSF: XRes ${kv.XRes}, YRes ${kv.YRes}: need positive integers`);
  }
  const start = (nul + 4) & ~3;
  const need = start + 4 * xres * yres;
  if (bytes.byteLength !== need) throw new Error(`GSF: ${bytes.byteLength} bytes, ${xres}×${yres} needs ${need}`);
  const v = new DataView(bytes.buffer, bytes.byteOffset + start, 4 * xres * yres);
  const heights = new Float32Array(xres * yres);
  for (let i = 0; i < heights.length; i++) heights[i] = v.getFloat32(4 * i, true);
  const num = (k, d) => (kv[k] !== undefined && Number.isFinite(Number(kv[k])) ? Number(kv[k]) : d);
  return {
    xres, yres, heights,
    x_real: num('XReal', 1), y_real: num('YReal', 1), x_offset: num('XOffset', 0), y_offset: num('YOffset', 0),
    title: kv.Title ?? '',
  };
}

/** What a finished push means, in words: `ok`, or the failure code, reason and record. */
export function describeRun(r) {
  const rec = r.record ? `record ${r.record}` : r.record_error ? `no record: ${r.record_error}` : 'no record';
  if (r.outcome === 'ok') {
    const at = Array.isArray(r.estimate) ? `, particle now at ${formatPoint(r.estimate)}` : '';
    return `push of #${r.particle} ok${at} (${rec})`;
  }
  const never = Array.isArray(r.estimate) ? `, particle left at ${formatPoint(r.estimate)}` : ', it never started';
  return `push of #${r.particle} failed: ${r.outcome}: ${r.failure ?? 'no reason given'}${never} (${rec})`;
}

/** The length unit that suits a size (m): nm below 2 µm, else µm. */
export function lengthUnit(sizeM) {
  return Math.abs(sizeM) < 2e-6 ? { name: 'nm', scale: 1e9 } : { name: 'µm', scale: 1e6 };
}

/** A length (m) with a unit chosen for `ref` (m; defaults to the value itself). */
export function formatLen(m, ref = m, digits = 3) {
  const u = lengthUnit(ref);
  const v = m * u.scale;
  return `${Number(v.toPrecision(digits))} ${u.name}`;
}

function formatPoint([x, y]) {
  const u = lengthUnit(Math.max(Math.abs(x), Math.abs(y)));
  return `(${(x * u.scale).toFixed(u.name === 'nm' ? 1 : 2)}, ${(y * u.scale).toFixed(u.name === 'nm' ? 1 : 2)}) ${u.name}`;
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
    lease: null, // holder's client id
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
    scan: null, // {id, xres, yres, x_offset, y_offset, x_real, y_real, heights, received, lines, min, max, done, record}
    strayLines: 0, // scan lines of no current scan
    runs: [], // run_done messages, newest last
    errors: [], // {at, id, code, message, command}
    lastError: null,
    commands: new Map(), // id → {id, type, msg, status: pending|ok|error, code, message}
    nextId: 1,
    particles: [], // from /api/scene, metres; moved by run_done estimates
    stageRange: 100e-6,
    shutdown: null,
  };
}

export class Session {
  constructor(opts) {
    this.state = initialState(opts);
  }

  /** Loads an /api/scene document: the particles and the stage range. */
  setScene(scene) {
    this.state.particles = sceneParticles(scene);
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
    const s = this.state;
    switch (msg.type) {
      case 'welcome':
        s.version = msg.version;
        s.client = msg.client;
        s.role = msg.role;
        s.lease = msg.lease ?? null;
        s.scene = msg.scene;
        s.tickHz = msg.tick_hz;
        s.stateReceived = false;
        if (msg.version !== WS_VERSION) {
          this.logError('version', `the server speaks protocol ${msg.version}, this page ${WS_VERSION}`);
        }
        return { kind: 'welcome' };
      case 'state': {
        s.stateReceived = true;
        s.lease = msg.lease ?? null;
        s.phase = msg.phase ?? null;
        if (Array.isArray(msg.stage)) s.tip = { t: null, stage: msg.stage, volts: 0, phase: msg.phase, estimate: null, force: 0 };
        for (const q of msg.particles ?? []) {
          const p = s.particles.find((pp) => pp.id === q.id);
          if (p) {
            p.x = q.x;
            p.y = q.y;
            p.radius = q.radius;
          } else {
            s.particles.push({ id: q.id, material: '', radius: q.radius, x: q.x, y: q.y });
          }
        }
        s.serverParticles = (msg.particles ?? []).map((q) => ({ ...q }));
        s.push = msg.push ?? null;
        const sc = msg.scan ?? null;
        let scanChanged = false;
        if (sc && (!s.scan || s.scan.id !== sc.scan)) {
          this.startScan({ ...sc, type: 'scan_start' });
          s.scan.done = !!sc.done;
          s.scan.record = sc.record ?? null;
          scanChanged = true;
        }
        s.scanStale = !!sc?.stale;
        return { kind: 'state', scan: sc, scanChanged };
      }
      case 'push_started':
        s.push = { particle: msg.particle, path: msg.path ?? [], by: msg.by ?? null };
        return { kind: 'push_started', push: s.push };
      case 'ok': {
        const c = msg.id != null ? s.commands.get(msg.id) : undefined;
        if (c) {
          c.status = 'ok';
          c.code = null;
          c.message = null;
        }
        return { kind: 'reply', ok: true, id: msg.id ?? null, command: c ?? null };
      }
      case 'error': {
        const c = msg.id != null ? s.commands.get(msg.id) : undefined;
        if (c) {
          c.status = 'error';
          c.code = msg.code;
          c.message = msg.message;
        }
        this.logError(msg.code, msg.message, msg.id);
        return { kind: 'reply', ok: false, id: msg.id ?? null, command: c ?? null };
      }
      case 'telemetry': {
        const force = Number.isFinite(msg.tip_force_n) ? msg.tip_force_n : 0;
        s.tip = { t: msg.t, stage: msg.stage, volts: msg.volts, phase: msg.phase, estimate: msg.estimate ?? null, force, haptic: msg.haptic ?? null };
        s.phase = msg.phase;
        s.telemetryCount++;
        const tr = s.trace;
        // A server restart starts its clock again: drop a trace that ran ahead.
        if (tr.t.length && msg.t < tr.t[tr.t.length - 1]) {
          tr.t.length = 0;
          tr.volts.length = 0;
          tr.z.length = 0;
          tr.force.length = 0;
        }
        tr.t.push(msg.t);
        tr.volts.push(msg.volts);
        tr.z.push(msg.stage[2]);
        tr.force.push(force);
        let drop = 0;
        while (drop < tr.t.length && tr.t[drop] < msg.t - tr.seconds) drop++;
        if (drop) {
          tr.t.splice(0, drop);
          tr.volts.splice(0, drop);
          tr.z.splice(0, drop);
          tr.force.splice(0, drop);
        }
        return { kind: 'telemetry' };
      }
      case 'lagged':
        s.lagged.events++;
        s.lagged.skipped += msg.skipped ?? 0;
        return { kind: 'lagged' };
      case 'lease': {
        const before = s.lease;
        const hadIt = before !== null && before === s.client;
        s.lease = msg.holder ?? null;
        s.leaseNote = msg.reason ?? null;
        const lost = hadIt && s.lease !== s.client;
        return { kind: 'lease', before, lost, reason: msg.reason ?? null };
      }
      case 'run_done': {
        s.lastRun = msg;
        s.push = null;
        if (Array.isArray(msg.estimate)) s.scanStale = s.scan !== null;
        s.runs.push(msg);
        if (s.runs.length > RUNS_MAX) s.runs.splice(0, s.runs.length - RUNS_MAX);
        const p = s.particles.find((q) => q.id === msg.particle);
        if (p && Array.isArray(msg.estimate)) {
          p.x = msg.estimate[0];
          p.y = msg.estimate[1];
        }
        const q = (s.serverParticles ?? []).find((qq) => qq.id === msg.particle);
        if (q && Array.isArray(msg.estimate)) {
          q.x = msg.estimate[0];
          q.y = msg.estimate[1];
        }
        return { kind: 'run_done', run: msg };
      }
      case 'scan_start':
        if (!this.startScan(msg)) return { kind: 'error' };
        return { kind: 'scan_start' };
      case 'scan_done':
        if (s.scan && s.scan.id === msg.scan) {
          s.scan.done = true;
          s.scan.record = msg.record ?? null;
        }
        return { kind: 'scan_done', record: msg.record ?? null, record_error: msg.record_error ?? null };
      case 'shutdown':
        s.shutdown = msg.reason ?? '';
        return { kind: 'shutdown' };
      default:
        return { kind: 'unknown', type: msg.type };
    }
  }

  /** A new, empty scan (from `scan_start`, `state` or a record); false when its size is absurd. */
  startScan(msg) {
    const s = this.state;
    {
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
          version: 0, // bumped by every change of the heights
        };
        return true;
    }
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

/**
 * What each operator control may do now, and why not: {enabled, why} per control. Viewers,
 * a closed connection, and commands that need the lease are explained in words (tooltips).
 */
export function controlState(state) {
  const open = state.connection === 'open' && state.client !== null;
  const operator = state.role === 'operator';
  const mine = open && state.lease !== null && state.lease === state.client;
  const no = (why) => ({ enabled: false, why });
  const yes = { enabled: true, why: '' };
  let base = null;
  if (!open) base = 'Not connected to the server';
  else if (!operator) base = 'Viewer connection: open the page with the operator token (?token=…) to command';
  const needLease = base ? no(base) : mine ? yes : state.lease === null ? no('Take the lease first') : no(`Client ${state.lease} holds the lease`);
  return {
    takeLease: base ? no(base) : mine ? no('You hold the lease') : state.lease !== null ? no(`Client ${state.lease} holds the lease`) : yes,
    releaseLease: base ? no(base) : mine ? yes : no('You do not hold the lease'),
    push: needLease,
    scan: needLease,
    haptic: needLease,
    stop: needLease,
  };
}
