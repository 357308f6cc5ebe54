// node --test: the Session (src/session.js) over sequences of the server's messages.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Session, controlState, sceneParticles, setPointForceN, describeRun, judgedText, runClass, lostPushRun, welcomeInstrument, OFFERS } from '../src/session.js';
import { WS_VERSION, encodeScanLine, commands } from '../src/wire.js';

test('session: welcome, lease changes and who may command', () => {
  const s = new Session();
  assert.equal(controlState(s.state).push.enabled, false);
  assert.match(controlState(s.state).push.why, /Not connected/);
  s.connecting();
  s.opened();
  s.apply('{"type":"welcome","version":1,"client":4,"role":"operator","lease":null,"scene":"gold","tick_hz":1000}');
  assert.equal(s.state.client, 4);
  assert.equal(s.state.role, 'operator');
  assert.equal(s.state.tickHz, 1000);
  assert.equal(s.hasLease, false);
  let c = controlState(s.state);
  assert.equal(c.takeLease.enabled, true);
  assert.equal(c.push.enabled, false);
  assert.equal(c.push.why, 'Take the lease first');

  assert.deepEqual(s.apply({ type: 'lease', holder: 4 }), { kind: 'lease', before: null, lost: false, reason: null });
  assert.equal(s.hasLease, true);
  c = controlState(s.state);
  assert.equal(c.push.enabled, true);
  assert.equal(c.scan.enabled, true);
  assert.equal(c.stop.enabled, true);
  assert.equal(c.takeLease.enabled, false);
  assert.equal(c.releaseLease.enabled, true);

  s.apply({ type: 'lease', holder: 9 });
  assert.equal(s.hasLease, false);
  c = controlState(s.state);
  assert.equal(c.push.why, 'Client 9 holds the lease');
  assert.equal(c.takeLease.enabled, false);

  s.apply({ type: 'lease', holder: null });
  assert.equal(s.state.lease, null);

  // A viewer may not command, and is told why.
  const v = new Session();
  v.opened();
  v.apply({ type: 'welcome', version: 1, client: 5, role: 'viewer', lease: 4, scene: 'x', tick_hz: 1000 });
  c = controlState(v.state);
  for (const k of ['takeLease', 'releaseLease', 'push', 'scan', 'stop']) {
    assert.equal(c[k].enabled, false, k);
    assert.match(c[k].why, /Viewer connection/);
  }
  assert.equal(v.state.lease, 4);

  // Closing forgets what the server said and fails the pending commands.
  const id = s.issue(commands.takeLease()).id;
  s.closed(1, 500);
  assert.equal(s.state.connection, 'closed');
  assert.deepEqual(s.state.reconnect, { attempt: 1, delayMs: 500 });
  assert.equal(s.state.client, null);
  assert.equal(s.state.commands.get(id).status, 'error');
  assert.equal(s.state.commands.get(id).code, 'disconnected');
});

test('session: a welcome of another protocol version is logged', () => {
  const s = new Session();
  s.apply({ type: 'welcome', version: WS_VERSION + 1, client: 1, role: 'viewer', lease: null, scene: 's', tick_hz: 1000 });
  assert.equal(s.state.lastError.code, 'version');
});

test('session: replies matched to their commands by id; errors in a log', () => {
  const s = new Session();
  s.apply({ type: 'welcome', version: 1, client: 1, role: 'operator', lease: null, scene: 's', tick_hz: 1000 });
  const a = s.issue(commands.takeLease());
  const b = s.issue(commands.pushBy(1, 5, 0));
  const c = s.issue(commands.scan({ pixels: 64 }));
  assert.deepEqual([a.id, b.id, c.id], [1, 2, 3]);
  assert.equal(b.distance_um, 5);
  assert.equal(s.state.commands.get(2).status, 'pending');

  const r = s.apply({ type: 'ok', id: 1 });
  assert.equal(r.kind, 'reply');
  assert.equal(r.ok, true);
  assert.equal(r.command.type, 'take_lease');
  assert.equal(s.state.commands.get(1).status, 'ok');

  assert.equal(s.apply({ type: 'error', id: 2, code: 'no_lease', message: 'push needs the lease' }).ok, false);
  const cmd = s.state.commands.get(2);
  assert.equal(cmd.status, 'error');
  assert.equal(cmd.code, 'no_lease');
  assert.equal(s.state.lastError.code, 'no_lease');
  assert.equal(s.state.lastError.command, 'push');
  assert.equal(s.state.lastError.id, 2);

  // An error with no id (a malformed message) is logged too.
  s.apply({ type: 'error', id: null, code: 'malformed', message: 'not JSON' });
  s.apply('{not json');
  s.apply({ no: 'type' });
  assert.deepEqual(s.state.errors.map((e) => e.code), ['no_lease', 'malformed', 'client_parse', 'client_parse']);
  assert.equal(s.state.commands.get(3).status, 'pending');

  // The log keeps the newest 50.
  for (let i = 0; i < 60; i++) s.apply({ type: 'error', id: null, code: 'rate_limited', message: `n${i}` });
  assert.equal(s.state.errors.length, 50);
  assert.equal(s.state.errors.at(-1).message, 'n59');
  assert.equal(s.state.lastError.message, 'n59');

  // Unknown message types are tolerated, those named like Object's methods too.
  assert.deepEqual(s.apply({ type: 'future_thing' }), { kind: 'unknown', type: 'future_thing' });
  for (const type of ['toString', 'constructor', '__proto__', 'hasOwnProperty']) {
    assert.deepEqual(s.apply({ type }), { kind: 'unknown', type }, type);
  }
  assert.equal(s.state.lastError.message, 'n59', 'and logged as no error');
});

test('session: lagged messages are counted; telemetry keeps a 10 s trace', () => {
  const s = new Session();
  s.apply({ type: 'lagged', skipped: 12 });
  s.apply({ type: 'lagged', skipped: 3 });
  assert.deepEqual(s.state.lagged, { events: 2, skipped: 15 });

  for (let i = 0; i <= 1200; i++) {
    const t = i / 60;
    s.apply({ type: 'telemetry', t, stage: [1e-6, 2e-6, 3e-9 * i], volts: -0.2 - i * 1e-3, phase: i < 1200 ? 'approach' : 'idle', estimate: null });
  }
  assert.equal(s.state.telemetryCount, 1201);
  assert.equal(s.state.phase, 'idle');
  assert.equal(s.state.tip.stage[0], 1e-6);
  const tr = s.state.trace;
  assert.equal(tr.t.length, tr.volts.length);
  assert.equal(tr.t.length, tr.z.length);
  assert.equal(tr.t.at(-1), 20);
  assert.ok(tr.t[0] >= 10 - 1e-9, `oldest ${tr.t[0]}`);
  assert.ok(tr.t.length >= 600 && tr.t.length <= 601, `${tr.t.length} samples`);
  assert.ok(Math.abs(tr.volts.at(-1) - (-0.2 - 1.2)) < 1e-12);

  // A server restart (time going back) starts the trace again.
  s.apply({ type: 'telemetry', t: 0.5, stage: [0, 0, 0], volts: 0, phase: 'idle', estimate: [1e-6, 1e-6] });
  assert.deepEqual(s.state.trace.t, [0.5]);
  assert.deepEqual(s.state.tip.estimate, [1e-6, 1e-6]);
  assert.equal(s.state.tip.seq, null, 'a frame without seq (the demo): nothing to acknowledge');
  s.apply({ type: 'telemetry', t: 0.6, seq: 42, stage: [0, 0, 0], volts: 0, phase: 'idle', estimate: null });
  assert.equal(s.state.tip.seq, 42, 'the frame to acknowledge');
});

test('session: a scan assembles its binary lines into the height array', () => {
  const s = new Session();
  const start = { type: 'scan_start', scan: 7, xres: 4, yres: 3, x_offset: 45e-6, y_offset: 40e-6, x_real: 10e-6, y_real: 10e-6 };
  assert.equal(s.apply(start).kind, 'scan_start');
  const sc = s.state.scan;
  assert.equal(sc.heights.length, 12);
  const line = (n, hs, scan = 7, xres = 4, yres = 3) => encodeScanLine({ scan, line: n, xres, yres, y: 40e-6 + n * 5e-6 }, hs);

  // Lines may arrive in any order.
  assert.deepEqual(s.apply(line(2, [9, 10, 11, 12])), { kind: 'scan_line', line: 2, y: 50e-6 });
  s.apply(line(0, [1, 2, 3, 4]));
  assert.equal(sc.lines, 2);
  assert.deepEqual([...sc.received], [1, 0, 1]);
  assert.equal(sc.min, 1);
  assert.equal(sc.max, 12);
  s.apply(new Uint8Array(line(1, [5, 6, 7, 8])));
  assert.deepEqual([...sc.heights], [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
  assert.equal(sc.lines, 3);
  // A repeated line replaces, and is not counted twice.
  s.apply(line(1, [5, 6, 7, -1]));
  assert.equal(sc.lines, 3);
  assert.equal(sc.heights[7], -1);
  assert.equal(sc.min, -1);

  // Lines of another scan are ignored; lines that do not fit are logged.
  assert.equal(s.apply(line(0, [0, 0, 0, 0], 6)).kind, 'stray_line');
  assert.equal(s.state.strayLines, 1);
  assert.equal(s.apply(line(0, [0, 0, 0], 7, 3, 3)).kind, 'error');
  assert.match(s.state.lastError.message, /3×3 does not fit the scan's 4×3/);
  assert.equal(s.apply(line(3, [0, 0, 0, 0])).kind, 'error');
  const bad = new Uint8Array(line(0, [0, 0, 0, 0]));
  bad[0] = 0;
  assert.equal(s.apply(bad).kind, 'error');
  assert.equal(s.state.lastError.code, 'client_frame');
  assert.match(s.state.lastError.message, /bad magic/);
  assert.equal(sc.heights[0], 1, 'a bad frame changes nothing');

  assert.deepEqual(s.apply({ type: 'scan_done', scan: 7, record: 'scan-7.gsf' }), { kind: 'scan_done', record: 'scan-7.gsf', record_error: null });
  assert.equal(sc.done, true);
  assert.equal(sc.record, 'scan-7.gsf');

  // A new scan replaces the old one.
  s.apply({ ...start, scan: 8, xres: 8, yres: 8 });
  assert.equal(s.state.scan.id, 8);
  assert.equal(s.state.scan.lines, 0);
  assert.equal(s.state.scan.heights.length, 64);
  assert.equal(s.apply({ ...start, scan: 9, xres: 0 }).kind, 'error');
  assert.equal(s.state.scan, null);
});

test('session: the scene\'s particles in metres; run_done moves the pushed one', () => {
  const scene = { name: 'g', particles: [{ id: 1, radius_nm: 500, x_um: 70, y_um: 45, material: 'latex' }, { id: 2, radius_nm: 7, x_um: 10, y_um: 20 }], stage: { range_um: 80 } };
  assert.deepEqual(sceneParticles(scene)[0], { id: 1, material: 'latex', radius: 500e-9, x: 70e-6, y: 45e-6 });
  assert.deepEqual(sceneParticles({}), []);
  const s = new Session();
  s.setScene(scene);
  assert.equal(s.state.particles.length, 2);
  assert.equal(s.state.stageRange, 80e-6);
  assert.equal(s.state.pushSpeed, null, 'no [push] speed: no time left for a push');
  s.setScene({ ...scene, push: { speed_um_per_s: 2 } });
  assert.equal(s.state.pushSpeed, 2e-6, 'the push speed in m/s');
  const r = s.apply({ type: 'run_done', particle: 2, outcome: 'ok', failure: null, estimate: [12e-6, 21e-6], record: 'push-1.csv' });
  assert.equal(r.kind, 'run_done');
  assert.deepEqual([s.state.particles[1].x, s.state.particles[1].y], [12e-6, 21e-6]);
  assert.deepEqual([s.state.particles[0].x, s.state.particles[0].y], [70e-6, 45e-6]);
  assert.equal(s.state.runs.length, 1);
  s.apply({ type: 'run_done', particle: 1, outcome: 'no_contact', failure: 'no contact within 10 µm', estimate: [70e-6, 45e-6], record: null });
  assert.equal(s.state.runs.at(-1).outcome, 'no_contact');
  s.apply({ type: 'shutdown', reason: 'SIGTERM' });
  assert.equal(s.state.shutdown, 'SIGTERM');
});

function openSession(client = 4) {
  const s = new Session();
  s.setScene({ stage: { range_um: 100 }, particles: [{ id: 1, radius_nm: 500, x_um: 40, y_um: 30 }, { id: 2, radius_nm: 500, x_um: 55, y_um: 62 }] });
  s.connecting();
  s.opened();
  s.apply({ type: 'welcome', version: 1, client, role: 'operator', lease: null, scene: 'g', tick_hz: 1000 });
  return s;
}

test('session: state after welcome: particles, lease, phase, push, scan', () => {
  const s = openSession(4);
  const ev = s.apply({
    type: 'state', particles: [{ id: 1, x: 45e-6, y: 31e-6, radius: 5e-7 }], stage: [1e-6, 2e-6, 3e-6], phase: 'pushing', lease: 9,
    push: { particle: 1, path: [[40e-6, 30e-6], [45e-6, 30e-6]], by: 9 },
    scan: { scan: 3, xres: 4, yres: 2, x_offset: 0, y_offset: 0, x_real: 1e-6, y_real: 1e-6, done: true, record: 'scan-1-3.gsf', stale: true },
  });
  assert.equal(ev.kind, 'state');
  assert.equal(ev.scanChanged, true);
  assert.equal(s.state.particles[0].x, 45e-6);
  assert.equal(s.state.particles[1].x, 55e-6, 'a particle the state leaves out stays');
  assert.equal(s.state.lease, 9);
  assert.equal(s.state.phase, 'pushing');
  assert.deepEqual(s.state.tip.stage, [1e-6, 2e-6, 3e-6]);
  assert.equal(s.state.push.by, 9);
  assert.equal(s.state.scan.id, 3);
  assert.equal(s.state.scan.record, 'scan-1-3.gsf');
  assert.equal(s.state.scanStale, true);
  assert.equal(s.fillScan(3, new Float32Array([1, 2, 3, 4, 5, 6, 7, 8])), true);
  assert.equal(s.state.scan.lines, 2);
  assert.equal(s.state.scan.max, 8);
  assert.equal(s.fillScan(4, new Float32Array(8)), false, 'another scan id');
  assert.equal(s.fillScan(3, new Float32Array(7)), false, 'another size');
  // A reconnect forgets what the old connection was told.
  s.closed(1, 500);
  assert.equal(s.state.phase, null);
  assert.equal(s.state.push, null);
  assert.equal(s.state.lease, null);
});

test('session: a push that never started is a run; it clears the push path', () => {
  const s = openSession(4);
  s.apply({ type: 'push_started', particle: 1, path: [[40e-6, 30e-6], [50e-6, 30e-6]], by: 4 });
  assert.deepEqual(s.state.push.path[1], [50e-6, 30e-6]);
  assert.equal(s.state.push.attempt, 1);
  s.apply({ type: 'push_started', particle: 1, path: [[40e-6, 30e-6]], by: 4, attempt: 1, warnings: ['w'], strategy: { summary: 'β = 30°', tried: [] } });
  assert.deepEqual([s.state.push.warnings, s.state.push.strategy.summary], [['w'], 'β = 30°']);
  const r = { type: 'run_done', particle: 1, outcome: 'plan', failure: 'particle 1: target out of reach', estimate: null, record: null, record_error: null };
  const ev = s.apply(r);
  assert.equal(ev.kind, 'run_done');
  assert.equal(s.state.push, null);
  assert.equal(s.state.particles[0].x, 40e-6, 'not moved: no estimate');
  assert.equal(describeRun(r), 'push of #1 failed: plan: particle 1: target out of reach, it never started (no record)');
  assert.equal(describeRun({ particle: 2, outcome: 'ok', estimate: [5e-5, 6e-5], record: 'push-1.csv' }), 'push of #2 ok, particle now at (50.00, 60.00) µm (record push-1.csv)');
  const judged = { measured: [5e-5, 6e-5], target: [5e-5, 6.0000002e-5], error_m: 2.49e-9, tolerance_m: 25e-9, attempts: 2 };
  assert.equal(describeRun({ particle: 2, outcome: 'ok', estimate: [5e-5, 6e-5], record: 'push-2.json', judged }),
    'push of #2 ok: measured 2.5 nm from the target (tolerance 25.0 nm), after 1 correction, particle now at (50.00, 60.00) µm (record push-2.json)');
  assert.equal(judgedText({ ...judged, attempts: 3 }), ': measured 2.5 nm from the target (tolerance 25.0 nm), after 2 corrections');
  assert.equal(judgedText(null), '');
  assert.equal(describeRun({ particle: 2, outcome: 'stopped', failure: 'stopped: stop requested by the operator', estimate: [5e-8, 6e-8], record: null, record_error: 'disk full' }),
    'push of #2 stopped: stop requested by the operator, particle left at (0.05, 0.06) µm (no record: disk full)');
  // The line under Stop leaves the record's name to the Records list and the log; a missing
  // record is still said.
  assert.equal(describeRun({ particle: 2, outcome: 'ok', estimate: [5e-5, 6e-5], record: 'push-2.json', judged }, { record: false }),
    'push of #2 ok: measured 2.5 nm from the target (tolerance 25.0 nm), after 1 correction, particle now at (50.00, 60.00) µm');
  assert.equal(describeRun(r, { record: false }), 'push of #1 failed: plan: particle 1: target out of reach, it never started (no record)');
});

test('session: losing the lease is told from a change elsewhere, with why', () => {
  const s = openSession(4);
  assert.equal(s.apply({ type: 'lease', holder: 4 }).lost, false);
  const ev = s.apply({ type: 'lease', holder: null, reason: 'client 4 disconnected' });
  assert.equal(ev.lost, true);
  assert.equal(ev.reason, 'client 4 disconnected');
  assert.equal(s.apply({ type: 'lease', holder: 7 }).lost, false);
});

test('session: tip force in the trace; a run_done after a scan marks it stale', () => {
  const s = openSession(4);
  s.apply({ type: 'telemetry', t: 1, stage: [0, 0, 1e-6], volts: 0.1, phase: 'idle', estimate: null, tip_force_n: 2.5e-9 });
  assert.deepEqual(s.state.trace.force, [2.5e-9], 'in N');
  s.apply({ type: 'scan_start', scan: 1, xres: 8, yres: 8, x_offset: 0, y_offset: 0, x_real: 1e-6, y_real: 1e-6 });
  assert.equal(s.state.scanStale, false);
  s.apply({ type: 'run_done', particle: 1, outcome: 'ok', failure: null, estimate: [41e-6, 30e-6], record: 'r', record_error: null });
  assert.equal(s.state.scanStale, true);
});

test('the set point as a tip force: its deflection times the stiffness', () => {
  // scenes/gold-latex-500nm.toml: set_point_v −1.5, baseline_v −0.2, gain_v_per_nm −0.4, k 8 N/m.
  const f = setPointForceN({ strategy: { set_point_v: -1.5 }, sensor: { baseline_v: -0.2, gain_v_per_nm: -0.4 }, cantilever: { stiffness_n_per_m: 8 } });
  assert.ok(Math.abs(f - 26e-9) < 1e-15, `−1.5 V is 3.25 nm of deflection, 26 nN at 8 N/m: ${f}`);
  assert.equal(setPointForceN({ strategy: {} }), null);
});

test('a stop is no failure: who stopped it, said once, neutral; a miss amber', () => {
  // Said once: the server's `failure` already starts "stopped: ".
  const stop = { particle: 1, outcome: 'stopped', failure: 'stopped: the lease holder disconnected', estimate: [1e-6, 2e-6], record: 'push-1.json' };
  assert.equal(describeRun(stop), 'push of #1 stopped: the lease holder disconnected, particle left at (1.00, 2.00) µm (record push-1.json)');
  assert.equal(runClass(stop), 'neutral');
  assert.equal(runClass({ outcome: 'ok' }), 'good');
  assert.equal(runClass({ outcome: 'plan' }), 'bad');
  const missed = { particle: 3, outcome: 'missed', failure: 'ended 0.40 µm from the target', estimate: [1e-6, 2e-6], record: 'push-2.json' };
  assert.equal(runClass(missed), 'warn');
  assert.match(describeRun(missed), /^push of #3 missed: ended 0\.40 µm from the target/);
});

test('a push running at a close is kept as lost; a restart told by instance', () => {
  const s = openSession(4);
  s.apply({ type: 'welcome', version: WS_VERSION, client: 4, role: 'operator', lease: 4, scene: 'g', tick_hz: 1000, instance: 'a-1', started_unix_ms: 1000 });
  assert.equal(s.state.instance, 'a-1');
  assert.equal(s.state.restarted, false, 'the first server seen is no restart');
  s.apply({ type: 'push_started', particle: 1, path: [[40e-6, 30e-6], [41e-6, 30e-6]], by: 4 });
  s.closed(1, 250);
  assert.equal(s.state.push, null, 'nothing runs that this page knows of');
  assert.deepEqual(s.state.lostPush.particle, 1, 'but the push it saw running is remembered');
  s.opened();
  const ev = s.apply({ type: 'welcome', version: WS_VERSION, client: 9, role: 'operator', lease: null, scene: 'g', tick_hz: 1000, instance: 'b-2', started_unix_ms: 5000 });
  assert.equal(ev.restarted, true);
  assert.equal(ev.previous, 'a-1');
  assert.equal(s.state.restarted, true);
  assert.equal(s.state.startedUnixMs, 5000);
  // The same server again (a network blip): no restart.
  s.closed(1, 250);
  s.opened();
  assert.equal(s.apply({ type: 'welcome', version: WS_VERSION, client: 10, role: 'operator', lease: null, scene: 'g', tick_hz: 1000, instance: 'b-2', started_unix_ms: 5000 }).restarted, false);
});

test('the haptic handle may be engaged only while its link is up', () => {
  const s = openSession(4);
  s.apply({ type: 'lease', holder: 4 });
  s.apply({ type: 'telemetry', t: 1, stage: [0, 0, 1e-6], volts: 0, phase: 'idle', estimate: null, haptic: { link: 'down', phase: 'off', tip_force_n: 0, pc_active: false } });
  let c = controlState(s.state);
  assert.equal(c.hapticEngage.enabled, false);
  assert.match(c.hapticEngage.why, /link is down/);
  assert.equal(c.haptic.enabled, true, 'release and the scales stay');
  s.apply({ type: 'telemetry', t: 2, stage: [0, 0, 1e-6], volts: 0, phase: 'idle', estimate: null, haptic: { link: 'up', phase: 'off', tip_force_n: 0, pc_active: false } });
  c = controlState(s.state);
  assert.equal(c.hapticEngage.enabled, true);
});

// The scan shown across a reconnect.
const welcomeOf = (instance, client = 5) => ({ type: 'welcome', version: WS_VERSION, client, role: 'viewer', lease: null, scene: 'g', tick_hz: 1000, instance, started_unix_ms: 1000 });
const scanOf = (id, extra = {}) => ({ scan: id, xres: 4, yres: 3, x_offset: 0, y_offset: 0, x_real: 1e-6, y_real: 1e-6, done: false, record: null, stale: false, ...extra });
const stateWith = (scan) => ({ type: 'state', particles: [], stage: [0, 0, 1e-6], phase: 'idle', lease: null, push: null, scan });

test('a scan that ended while away (same server) is done and fetched whole', () => {
  const s = openSession(5);
  s.apply(welcomeOf('a-1'));
  s.apply(stateWith(scanOf(3)));
  s.apply(encodeScanLine({ scan: 3, line: 0, xres: 4, yres: 3, y: 0 }, [1e-9, 2e-9, 3e-9, 4e-9]));
  s.closed(1, 250);
  s.opened();
  s.apply(welcomeOf('a-1', 6));
  const ev = s.apply(stateWith(scanOf(3, { done: true, record: 'scan-1-3.gsf' })));
  assert.equal(s.state.scan.done, true, 'the server says scan 3 is done');
  assert.equal(s.state.scan.record, 'scan-1-3.gsf');
  assert.equal(ev.scanFinished, true, 'the page is told to fetch the lines it missed');
  assert.equal(ev.scanChanged, false);
});

test('after a restart the previous run\'s scan is never the new one\'s', () => {
  const s = openSession(5);
  s.apply(welcomeOf('a-1'));
  s.apply(stateWith(scanOf(1)));
  s.apply(encodeScanLine({ scan: 1, line: 0, xres: 4, yres: 3, y: 0 }, [1e-9, 2e-9, 3e-9, 4e-9]));
  s.closed(1, 250);
  s.opened();
  s.apply(welcomeOf('b-2', 1));
  s.apply(stateWith(null));
  assert.equal(s.state.scan.interrupted, true, 'scan 1 of the killed server never ends');
  assert.equal(s.state.scanStale, true, 'the restarted server\'s sample is not what it shows');
  // The new server's scan 1 is another scan, though it has the same number.
  const ev = s.apply(stateWith(scanOf(1, { done: true, record: 'scan-9-1.gsf' })));
  assert.equal(ev.scanChanged, true);
  assert.equal(s.state.scan.interrupted, false);
  assert.equal(s.state.scan.record, 'scan-9-1.gsf');
  assert.equal(s.state.scanStale, false);
});

test('a lost push is matched to its own record, never to an earlier push', () => {
  const s = openSession(4);
  s.apply({ type: 'welcome', version: WS_VERSION, client: 4, role: 'operator', lease: 4, scene: 'g', tick_hz: 1000, instance: 'a-1', started_unix_ms: 1000 });
  s.apply({ type: 'push_started', particle: 1, path: [[40e-6, 30e-6], [41e-6, 30e-6]], by: 4, run: 2 });
  s.closed(1, 250);
  const lost = s.state.lostPush;
  assert.equal(lost.run, 2);
  assert.equal(lost.instance, 'a-1');
  const now = Date.now() / 1000;
  // Run 1 of the same particle ended a second before run 2 began; run 2 was killed (no record);
  // the restarted server ('b-2') already has a run 2 of that particle too.
  const runs = [
    { record: 'push-9-r2-p1.json', modified: Math.floor(now) + 5, instance: 'b-2', run: 2, particle: 1, outcome: 'ok' },
    { record: 'push-8-r1-p1.json', modified: Math.floor(now) - 1, instance: 'a-1', run: 1, particle: 1, outcome: 'ok' },
  ];
  assert.equal(lostPushRun(runs, lost), null, 'killed: no record of it');
  const own = { record: 'push-8-r2-p1.json', modified: Math.floor(now), instance: 'a-1', run: 2, particle: 1, outcome: 'stopped', failure: 'stopped: the lease holder disconnected' };
  assert.equal(lostPushRun([runs[0], own, runs[1]], lost), own, 'server run a-1, run 2, particle 1');
  assert.equal(lostPushRun(null, lost), null);
});

const NANONIS = { backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: [] };

test('the instrument from the welcome: an older server\'s is the simulated AFM offering everything', () => {
  const s = openSession(4);
  assert.deepEqual(s.state.instrument, { backend: 'simulated AFM', feed_rate_hz: 1000, z_closed_locally: false, read_only: false, offers: [...OFFERS] });
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000, instrument: { ...NANONIS, read_only: true } });
  assert.deepEqual(s.state.instrument, { ...NANONIS, read_only: true });
  s.closed(1, 250);
  assert.deepEqual(s.state.instrument, { ...NANONIS, read_only: true }, 'kept while disconnected: the last known');
  assert.equal(new Session().state.instrument, null, 'none before a welcome');
  // What a server may leave out: no offers is none offered; a rate that is no rate is unknown.
  assert.deepEqual(welcomeInstrument({ tick_hz: 1000, instrument: { backend: '', feed_rate_hz: 'fast' } }),
    { backend: 'unnamed instrument', feed_rate_hz: null, z_closed_locally: false, read_only: false, offers: [] });
});

test('a real controller: push, scan, assemble and the haptic handle off and why, before the lease; Stop and the lease as ever', () => {
  const s = openSession(4);
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000, instrument: NANONIS });
  let c = controlState(s.state);
  assert.equal(c.push.enabled, false);
  assert.equal(c.push.why, 'Pushes from the page run on the simulated AFM; on this controller use nanopush push --instrument', 'not "Take the lease first"');
  assert.match(c.scan.why, /^Scans from the page run on the simulated AFM; on this controller use nanopush scan --instrument$/);
  assert.match(c.assemble.why, /^Assemblies from the page/);
  assert.match(c.haptic.why, /^The haptic handle runs on the simulated AFM/);
  assert.equal(c.takeLease.enabled, true);
  assert.equal(c.stop.why, 'Take the lease first');
  s.apply({ type: 'lease', holder: 4 });
  s.apply({ type: 'telemetry', t: 1, stage: [0, 0, 1e-6], volts: 0.2, phase: 'idle', estimate: null });
  c = controlState(s.state);
  for (const k of ['push', 'scan', 'assemble', 'haptic', 'hapticEngage']) assert.equal(c[k].enabled, false, k);
  assert.equal(c.hapticEngage.why, c.haptic.why);
  assert.equal(c.stop.enabled, true, 'Stop withdraws the tip on a real controller too');
  assert.equal(c.releaseLease.enabled, true);
  // Offers one by one: only what is missing is off.
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: 4, scene: 'g', tick_hz: 1000, instrument: { ...NANONIS, offers: ['scan'] } });
  c = controlState(s.state);
  assert.equal(c.scan.enabled, true);
  assert.equal(c.push.enabled, false);
  // The connection and the role come first.
  s.closed(1, 250);
  assert.equal(controlState(s.state).push.why, 'Not connected to the server');
  const v = new Session();
  v.opened();
  v.apply({ type: 'welcome', version: 1, client: 5, role: 'viewer', lease: null, scene: 'g', tick_hz: 1000, instrument: NANONIS });
  assert.match(controlState(v.state).push.why, /^Viewer connection/);
});

test('on a real controller the scene\'s particles are not drawn, whichever comes first', () => {
  const scene = { particles: [{ id: 1, x_um: 40, y_um: 30, radius_nm: 500 }], stage: { range_um: 100 } };
  const welcome = { type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000, instrument: NANONIS };
  const first = new Session();
  first.setScene(scene);
  assert.equal(first.state.particles.length, 1);
  first.apply(welcome);
  assert.deepEqual(first.state.particles, [], 'the welcome after the scene clears them');
  const second = new Session();
  second.apply(welcome);
  second.setScene(scene);
  assert.deepEqual(second.state.particles, [], 'the scene after the welcome adds none');
  const sim = new Session();
  sim.apply({ ...welcome, instrument: undefined });
  sim.setScene(scene);
  assert.equal(sim.state.particles.length, 1, 'the simulated AFM draws the scene');
});
