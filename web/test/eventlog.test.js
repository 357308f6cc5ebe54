// node --test: the event log's lines for the server's events (src/eventlog.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  welcomeText, stateText, scanSize, scanDoneNote, pusher, pushStartedText, pushStrategy, pushWarnings, leaseNote, replyErrorText, closedText, LEASE_LOST_ON_CLOSE, lostOnCloseText,
} from '../src/eventlog.js';
import { Session } from '../src/session.js';

test('welcome and state', () => {
  const s = new Session();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'gold', tick_hz: 1000 });
  assert.equal(welcomeText(s.state), 'welcome: client 4, operator, scene gold, simulated AFM · 1 kHz loop', 'an older server: the simulated AFM at its tick rate');
  s.apply({ type: 'state', particles: [], phase: 'idle', lease: null });
  assert.equal(stateText(s.state), 'state: phase idle, lease free');
  s.apply({
    type: 'state', particles: [], phase: 'pushing', lease: 9, push: { particle: 1, path: [[0, 0], [1e-6, 0]], by: 9 },
    scan: { scan: 3, xres: 8, yres: 8, x_offset: 0, y_offset: 0, x_real: 1e-6, y_real: 1e-6, done: true, record: 'scan-1-3.gsf', stale: true },
  });
  assert.equal(stateText(s.state), 'state: phase pushing, lease held by client 9, pushing #1, latest scan scan-1-3.gsf (stale)');
  s.apply({ type: 'state', particles: [], lease: null, scan: { scan: 4, xres: 8, yres: 8, x_offset: 0, y_offset: 0, x_real: 1e-6, y_real: 1e-6 } });
  assert.equal(stateText(s.state), 'state: phase –, lease free, latest scan 4');
});

test('scans: started (size), done (a record, an error, cancelled)', () => {
  assert.equal(scanSize({ xres: 32, yres: 16, x_real: 10e-6 }), '32×16 px, 10.0 µm square');
  assert.equal(scanSize({ xres: 64, yres: 64, x_real: 200e-9 }), '64×64 px, 200 nm square');
  assert.deepEqual(scanDoneNote({ record: 'scan-7.gsf', record_error: null }), { text: 'scan done: scan-7.gsf', cls: 'good' });
  assert.deepEqual(scanDoneNote({ record: null, record_error: 'disk full' }), { text: 'scan done, no record: disk full', cls: 'bad' });
  assert.deepEqual(scanDoneNote({ record: null, record_error: null }), { text: 'scan cancelled', cls: 'bad' });
});

test('a push started, by this client or another, in one leg or more', () => {
  const p = { particle: 2, path: [[40e-6, 30e-6], [45e-6, 30e-6]], by: 4 };
  assert.equal(pusher(p, 4), 'you');
  assert.equal(pushStartedText(p, 4), 'push started: #2 by you, to (45.000, 30.000) µm in 1 leg');
  assert.equal(pushStartedText({ ...p, path: [...p.path, [45e-6, 31e-6]] }, 5), 'push started: #2 by client 4, to (45.000, 31.000) µm in 2 legs');
  assert.equal(pushStartedText({ ...p, attempt: 2 }, 4),
    'correction 1 of #2: the scan after the push found it outside the tolerance; pushing it from (40.000, 30.000) µm to (45.000, 30.000) µm in 1 leg');
  assert.deepEqual(pushWarnings({ ...p, warnings: ['strategy.start_height_um = 1.2 (hand-set): below the 1.26 µm'] }),
    ['plan warning for #2: strategy.start_height_um = 1.2 (hand-set): below the 1.26 µm']);
  assert.deepEqual(pushWarnings(p), []);
  const strategy = { summary: 'β = 30°, read on the pull side, xy control, 1 µm/s, pushes of at most 20 µm: why', tried: ['β = 45°, push side: unreadable'] };
  assert.deepEqual(pushStrategy({ ...p, strategy }),
    ['strategy for #2: β = 30°, read on the pull side, xy control, 1 µm/s, pushes of at most 20 µm: why', '  tried first: β = 45°, push side: unreadable']);
  assert.deepEqual(pushStrategy(p), []);
  assert.deepEqual(pushStrategy({ ...p, strategy: { summary: 3 } }), []);
});

test('the lease: taken, lost (said aloud), changed elsewhere, with reasons', () => {
  const s = new Session();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000 });
  let ev = s.apply({ type: 'lease', holder: 4 });
  assert.deepEqual(leaseNote(ev, s.state), { text: 'you hold the lease', cls: '', announce: null });
  ev = s.apply({ type: 'lease', holder: null, reason: 'client 4 idle for 60 s' });
  assert.deepEqual(leaseNote(ev, s.state), { text: 'you lost the lease: client 4 idle for 60 s', cls: 'bad', announce: 'you lost the lease: client 4 idle for 60 s' });
  ev = s.apply({ type: 'lease', holder: 7 });
  assert.deepEqual(leaseNote(ev, s.state), { text: 'client 7 holds the lease', cls: '', announce: null });
  ev = s.apply({ type: 'lease', holder: null, reason: 'client 7 disconnected' });
  assert.deepEqual(leaseNote(ev, s.state), { text: 'the lease is free: client 7 disconnected', cls: 'bad', announce: 'client 7 disconnected' });
  s.apply({ type: 'lease', holder: 4 });
  ev = s.apply({ type: 'lease', holder: 7 });
  assert.deepEqual(leaseNote(ev, s.state), { text: 'you lost the lease: client 7 holds the lease', cls: 'bad', announce: 'you lost the lease: client 7 holds the lease' });
});

test('the welcome names the backend: the simulated AFM, or a real controller', () => {
  const s = new Session();
  const inst = { backend: 'simulated AFM', feed_rate_hz: 500, z_closed_locally: false, read_only: false, offers: ['push', 'scan', 'assemble', 'haptic'] };
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'gold', tick_hz: 500, instrument: inst });
  assert.equal(welcomeText(s.state), 'welcome: client 4, operator, scene gold, simulated AFM · 500 Hz loop');
  s.apply({
    type: 'welcome', version: 1, client: 5, role: 'operator', lease: null, scene: 'gold', tick_hz: 1000,
    instrument: { backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: [] },
  });
  assert.equal(welcomeText(s.state), 'welcome: client 5, operator, scene gold, Nanonis 127.0.0.1:6501 · signals at 1 kHz · force held by the controller');
});

test('errors and a closed connection', () => {
  assert.equal(replyErrorText({ id: 3 }, { code: 'no_lease', message: 'push needs the lease' }), 'error #3 no_lease: push needs the lease');
  assert.equal(replyErrorText({ id: null }, { code: 'malformed', message: 'not JSON' }), 'error malformed: not JSON');
  assert.equal(closedText({ code: 1006, reason: '' }), 'connection closed (code 1006)');
  assert.equal(closedText({ code: 1001, reason: 'going away' }), 'connection closed (code 1001, going away)');
  assert.match(LEASE_LOST_ON_CLOSE, /^you lost the lease: the connection closed/);
});

test('the lease holder is named where the server names them', () => {
  const s = new Session();
  s.apply({ type: 'welcome', version: 1, client: 2, role: 'viewer', name: 'bob', lease: 5, lease_name: 'alice', scene: 'x', tick_hz: 1000 });
  assert.equal(welcomeText(s.state), 'welcome: client 2 (bob), viewer, scene x, simulated AFM · 1 kHz loop');
  s.apply({ type: 'lease', holder: 7, holder_name: 'carol' });
  assert.deepEqual(leaseNote({ lost: false, reason: null }, s.state), { text: 'carol (client 7) holds the lease', cls: '', announce: null });
  s.apply({ type: 'lease', holder: null });
  assert.equal(s.state.leaseName, null);
});

test('a push lost with the connection: unknown until the server is back', () => {
  const push = { particle: 4, path: [[0, 0], [1e-6, 0]], by: 2 };
  assert.equal(lostOnCloseText(push, false), 'the connection closed while the push of #4 ran: its outcome is unknown until the server is back');
  const mine = lostOnCloseText(push, true);
  assert.match(mine, /^the connection closed while the push of #4 ran: its outcome is unknown until the server is back\. You lost the lease/);
  // The page cannot tell a dead server from a lost network: neither is said as a fact.
  assert.match(mine, /a server still running stops a push whose lease holder is gone, and a server that stopped stopped it/);
  assert.match(LEASE_LOST_ON_CLOSE, /a server still running frees it/);
});
