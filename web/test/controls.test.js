// node --test: what the operator's controls mean (src/controls.js): the push and scan commands
// from the forms, the push preview, the target picked in the 3D view, the replies by command id.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  REPLY_OUTPUT, Replies, readNumber, replyText, pushEndedText, particleLabel, clampTarget, pushCommand, pushPreview, previewLine,
  stopRefusedText, scanFormDefaults, toleranceField, whyText, realController,
} from '../src/controls.js';
import { Session, controlState } from '../src/session.js';
import { WS_VERSION } from '../src/wire.js';

test('form numbers: empty is the server\'s default (undefined), junk is NaN (refused by the builders)', () => {
  assert.equal(readNumber(''), undefined);
  assert.equal(readNumber('  '), undefined);
  assert.equal(readNumber(' 2.5 '), 2.5);
  assert.ok(Number.isNaN(readNumber('abc')));
  assert.throws(() => pushCommand('by', 1, { distance: readNumber('abc'), direction: 0 }, 100), /distance_um must be a finite number/);
});

test('the push form: by distance or to a target inside the stage', () => {
  assert.deepEqual(pushCommand('by', 2, { distance: 5, direction: 90, toX: 1, toY: 1 }, 100),
    { type: 'push', particle: 2, distance_um: 5, direction_deg: 90 });
  assert.deepEqual(pushCommand('to', 2, { distance: 5, direction: 90, toX: 30, toY: 40.5 }, 100),
    { type: 'push', particle: 2, to_x_um: 30, to_y_um: 40.5 });
  assert.throws(() => pushCommand('to', 2, { toX: 60, toY: 10 }, 50), /to_x_um must be in \[0, 50\]/, 'the stage of the scene, not 100 µm');
});

test('the push form\'s tolerance: the range and default the server\'s welcome states', () => {
  const session = new Session();
  session.apply(JSON.stringify({ type: 'welcome', version: WS_VERSION, client: 1, role: 'operator', lease: null, scene: 's', tick_hz: 1000,
    push_tolerance_nm: { default: 20, min: 2, max: 500 } }));
  const t = session.state.pushTolerance;
  assert.deepEqual(t, { default: 20, min: 2, max: 500 });
  assert.deepEqual(toleranceField(t), { min: '2', max: '500', value: '20' }, 'the form starts at the default');
  const push = (tolerance, bounds = t) => pushCommand('by', 2, { distance: 5, direction: 0, tolerance }, 100, bounds);
  // Sent when given, the server's default when the field is empty.
  assert.deepEqual(push(10), { type: 'push', particle: 2, distance_um: 5, direction_deg: 0, tolerance_nm: 10 });
  assert.equal(push(undefined).tolerance_nm, undefined);
  assert.equal(push(2).tolerance_nm, 2);
  assert.equal(push(500).tolerance_nm, 500);
  assert.throws(() => push(1.5), /tolerance_nm must be in \[2, 500\] nm, got 1.5/);
  assert.throws(() => push(501), /tolerance_nm must be in \[2, 500\] nm, got 501/);
  assert.throws(() => push(NaN), /tolerance_nm must be a finite number/);
  // A server that states none (an older one, the demo): the page checks only that it is a
  // number and leaves the range to the server; the field starts empty.
  assert.equal(push(501, null).tolerance_nm, 501);
  assert.deepEqual(toleranceField(null), { min: '', max: '', value: '' });
});

test('a target picked in the 3D view stays on the stage', () => {
  assert.deepEqual(clampTarget(-3, 120, 100), [0, 100]);
  assert.deepEqual(clampTarget(12.5, 40, 50), [12.5, 40]);
});

test('the push preview: the lease holder\'s, while no push runs; by distance or towards the target', () => {
  const p = { x: 40e-6, y: 30e-6, radius: 0.5e-6 };
  const from = { x: 40, y: 30, z: 0.5 };
  const base = { running: false, hasLease: true, mode: 'by', distance: 5, direction: 90 };
  assert.deepEqual(pushPreview(p, base), { target: null, preview: { from, deg: 90, lengthUm: 5 } });
  assert.deepEqual(pushPreview(p, { ...base, distance: undefined, direction: undefined }).preview, { from, deg: 0, lengthUm: 0 });
  const none = { target: null, preview: null };
  assert.deepEqual(pushPreview(p, { ...base, running: true }), none, 'a push runs: its path is shown instead');
  assert.deepEqual(pushPreview(p, { ...base, hasLease: false }), none, 'viewers and operators without the lease');
  assert.deepEqual(pushPreview(undefined, base), none, 'no particle selected');
  const to = pushPreview(p, { ...base, mode: 'to', toX: 43, toY: 34 });
  assert.deepEqual(to.target, { x: 43, y: 34 });
  assert.equal(to.preview.lengthUm, 5);
  assert.ok(Math.abs(to.preview.deg - (Math.atan2(4, 3) * 180) / Math.PI) < 1e-12);
  assert.deepEqual(pushPreview(p, { ...base, mode: 'to', toX: 43, toY: undefined }), none, 'no target yet');
});

test('texts: particles in the list, replies in words', () => {
  assert.equal(particleLabel({ id: 1, material: 'gold-coated latex', radius: 500e-9 }), '#1 gold-coated latex (r 500 nm)');
  assert.equal(particleLabel({ id: 2, material: '', radius: 7e-9 }), '#2 (r 7.0 nm)');
  assert.equal(replyText({ id: 3, type: 'take_lease', status: 'ok' }), 'lease taken');
  // A push's ok means accepted, not done well: how it ended comes with run_done.
  assert.equal(replyText({ id: 5, type: 'push', status: 'ok' }), 'push accepted: running');
  assert.equal(replyText({ id: 4, type: 'push', status: 'error', code: 'no_lease', message: 'push needs the lease' }), 'refused: push needs the lease');
  assert.equal(replyText({ id: 6, type: 'scan', status: 'error', code: 'disconnected', message: 'the connection closed before a reply' }),
    'no answer: the connection closed before the server replied');
});

test('the push\'s reply once it ended: its outcome in a word or two', () => {
  assert.equal(pushEndedText({ outcome: 'ok' }), 'push ended: ok');
  assert.equal(pushEndedText({ outcome: 'stopped' }), 'push ended: stopped');
  assert.equal(pushEndedText({ outcome: 'missed' }), 'push ended: missed the target');
  assert.equal(pushEndedText({ outcome: 'no_contact' }), 'push ended: failed (no contact)');
});

test('the map\'s preview: 5 µm at 90° from (40, 30) µm ends at (40, 35) µm', () => {
  const l = previewLine({ from: { x: 40, y: 30, z: 0.5 }, deg: 90, lengthUm: 5 });
  assert.ok(Math.abs(l.from[0] - 40e-6) < 1e-15 && Math.abs(l.from[1] - 30e-6) < 1e-15, `${l.from}`);
  assert.ok(Math.abs(l.to[0] - 40e-6) < 1e-15 && Math.abs(l.to[1] - 35e-6) < 1e-15, `${l.to}`);
  const r = previewLine({ from: { x: 40, y: 30, z: 0.5 }, deg: 0, lengthUm: 2 });
  assert.ok(Math.abs(r.to[0] - 42e-6) < 1e-15 && Math.abs(r.to[1] - 30e-6) < 1e-15, '0° is +x');
  assert.equal(previewLine({ from: { x: 40, y: 30, z: 0.5 }, deg: 0, lengthUm: 0 }), null, 'nothing to show');
  assert.equal(previewLine(null), null);
});

test('Stop that cannot act says why: no server, or the controls\' reason', () => {
  assert.match(stopRefusedText({ connection: 'closed' }, 'Not connected to the server'),
    /^Stop cannot reach the server \(not connected\)\. A running server stops a push whose lease holder is gone on its own\.$/);
  assert.equal(stopRefusedText({ connection: 'open' }, 'Take the lease first'), 'Stop not sent: take the lease first.');
});

test('the scan form starts at the scene\'s own scan, pixels within [8, 512]', () => {
  assert.deepEqual(scanFormDefaults({ scan: { size_um: 0.2, pixels: 1024 } }), { size: '0.2', pixels: '512' });
  assert.deepEqual(scanFormDefaults({ scan: { pixels: 4 } }), { pixels: '8' });
  assert.deepEqual(scanFormDefaults({}), {});
  // 50 µm at 256 px (195 nm a pixel) cannot show a 14 nm particle: the default scan
  // is made small enough for the smallest particle to span 2 pixels (14 nm × 256 / 2 = 1.8 µm).
  assert.deepEqual(scanFormDefaults({ scan: { size_um: 50, pixels: 256 }, particles: [{ radius_nm: 7 }, { radius_nm: 50 }] }), { size: '1.8', pixels: '256' });
  assert.deepEqual(scanFormDefaults({ scan: { size_um: 16, pixels: 32 }, particles: [{ radius_nm: 500 }] }), { size: '16', pixels: '32' }, 'big enough already');
});

test('replies show in their command\'s output, only for the latest command sent there', () => {
  const els = {};
  const $ = (id) => (els[id] ??= { className: '', textContent: '', title: '' });
  const r = new Replies($);
  r.sent({ type: 'take_lease', id: 1 });
  assert.deepEqual(els['reply-lease'], { className: 'reply pending', textContent: 'sending…', title: 'command take_lease #1' });
  r.sent({ type: 'release_lease', id: 2 }); // the same output
  r.replied({ id: 1, command: { id: 1, type: 'take_lease', status: 'ok' } });
  assert.equal(els['reply-lease'].title, 'command release_lease #2', 'a stale reply does not overwrite');
  r.replied({ id: 2, command: { id: 2, type: 'release_lease', status: 'error', code: 'no_lease', message: 'you do not hold it' } });
  assert.deepEqual(els['reply-lease'], { className: 'reply error', textContent: 'refused: you do not hold it', title: 'command release_lease #2 (no_lease)' });
  r.sent({ type: 'subscribe', id: 3 });
  r.replied({ id: 3, command: { id: 3, type: 'subscribe', status: 'ok' } });
  r.replied({ id: 9, command: null });
  assert.deepEqual(Object.keys(els), ['reply-lease'], 'subscribe has no output');
  assert.deepEqual(new Set(Object.values(REPLY_OUTPUT)), new Set(['reply-lease', 'reply-push', 'reply-scan', 'reply-stop', 'reply-haptic', 'reply-assemble']));
});

test('a command left without a reply by a closed connection says so', () => {
  const els = {};
  const $ = (id) => (els[id] ??= { className: '', textContent: '', title: '' });
  const r = new Replies($);
  const s = new Session();
  r.sent(s.issue({ type: 'scan' }));
  r.sent(s.issue({ type: 'take_lease' }));
  s.state.commands.get(2).status = 'ok';
  s.closed(1, 250);
  r.closed(s.state.commands);
  assert.equal(els['reply-scan'].textContent, 'no answer: the connection closed before the server replied');
  assert.equal(els['reply-lease'].textContent, 'sending…', 'answered before the close: left as it was');
});

test('the note under Stop: each reason once (the lease\'s for both, a real controller\'s for each)', () => {
  const s = new Session();
  s.opened();
  s.apply({ type: 'welcome', version: WS_VERSION, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000 });
  assert.equal(whyText(controlState(s.state)), 'Take the lease first');
  s.apply({ type: 'lease', holder: 4 });
  assert.equal(whyText(controlState(s.state)), '');
  s.apply({
    type: 'welcome', version: WS_VERSION, client: 4, role: 'operator', lease: 4, scene: 'g', tick_hz: 1000,
    instrument: { backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: [] },
  });
  assert.equal(whyText(controlState(s.state)),
    'Pushes from the page run on the simulated AFM; on this controller use nanopush push --instrument. Scans from the page run on the simulated AFM; on this controller use nanopush scan --instrument');
});

test('a real controller is told apart from the simulated AFM and from an unknown one', () => {
  assert.equal(realController({ instrument: null }), false, 'before a welcome: nothing known');
  assert.equal(realController({ instrument: { backend: 'simulated AFM' } }), false);
  assert.equal(realController({ instrument: { backend: 'Nanonis 127.0.0.1:6501' } }), true);
});
