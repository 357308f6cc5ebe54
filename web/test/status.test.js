// node --test: the status bar's words for a Session state (src/status.js), and StatusBar writing
// them into (fake) elements.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { statusFields, StatusBar } from '../src/status.js';
import { Session } from '../src/session.js';

test('before and while connecting, open (or the demo), and closed', () => {
  const s = new Session();
  let f = statusFields(s.state);
  assert.deepEqual(f.conn, { kind: 'closed', text: 'closed' }, 'idle, no reconnect due');
  assert.deepEqual([f.role, f.client, f.lease.text, f.phase, f.lagged, f.error.text, f.error.cls], ['–', '–', 'free', '–', '0', 'none', '']);
  s.connecting();
  assert.deepEqual(statusFields(s.state).conn, { kind: 'connecting', text: 'connecting…' });
  s.opened();
  assert.deepEqual(statusFields(s.state).conn, { kind: 'open', text: 'connected' });
  assert.deepEqual(statusFields(s.state, { demo: true }).conn, { kind: 'open', text: 'demo (no server)' });
  s.closed(2, 1000);
  assert.equal(statusFields(s.state).conn, null, 'the countdown speaks while a reconnect is due');
  s.closed(0, 0);
  assert.deepEqual(statusFields(s.state).conn, { kind: 'closed', text: 'closed' });
});

test('the lease (mine or another\'s), the phase, lags and the last error', () => {
  const s = new Session();
  s.opened();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: 4, scene: 'g', tick_hz: 1000 });
  let f = statusFields(s.state);
  assert.deepEqual([f.role, f.client, f.lease], ['operator', '4', { text: 'you (4)', cls: 'mine' }]);
  s.apply({ type: 'lease', holder: 9 });
  s.apply({ type: 'lagged', skipped: 12 });
  s.apply({ type: 'lagged', skipped: 3 });
  s.apply({ type: 'telemetry', t: 1, stage: [0, 0, 0], volts: 0, phase: 'contact_search' });
  const id = s.issue({ type: 'push' }).id;
  s.apply({ type: 'error', id, code: 'no_lease', message: 'push needs the lease' });
  f = statusFields(s.state);
  assert.deepEqual(f.lease, { text: 'client 9', cls: '' });
  assert.equal(f.phase, 'finding the particle\'s edge', 'the phase in words');
  assert.equal(f.lagged, '2× (15 msgs)');
  assert.deepEqual(f.error, { text: `no_lease (#${id} push): push needs the lease`, cls: 'err' });
  s.apply('{oops');
  assert.match(statusFields(s.state).error.text, /^client_parse: a text frame is not JSON/);
});

test('StatusBar writes the fields into the page', () => {
  const el = (extra = {}) => ({ textContent: '', className: '', title: '', ...extra });
  const txt = el();
  const els = { 'st-conn': el({ querySelector: () => txt }), 'instrument-status': el(), 'st-role': el(), 'st-client': el(), 'st-lease': el(), 'st-phase': el(), 'st-lagged': el(), 'st-error': el() };
  const bar = new StatusBar((id) => els[id]);
  const s = new Session();
  s.opened();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'viewer', lease: 4, scene: 'g', tick_hz: 1000 });
  s.logError('client_socket', 'not connected');
  bar.render(s.state);
  assert.equal(els['st-conn'].className, 'conn-open');
  assert.equal(txt.textContent, 'connected');
  assert.equal(els['st-role'].textContent, 'viewer');
  assert.equal(els['instrument-status'].textContent, 'Simulated AFM · 1 kHz loop');
  assert.match(els['instrument-status'].title, /^The simulated AFM: the server's control loop runs it at 1 kHz/);
  assert.equal(els['instrument-status'].className, '');
  assert.equal(els['st-lease'].className, 'mine');
  assert.equal(els['st-error'].title, 'client_socket: not connected');
  assert.equal(els['st-error'].className, 'err');
  bar.setConn('closed', 'reconnecting in 1.0 s (attempt 2)');
  assert.equal(els['st-conn'].className, 'conn-closed');
  assert.equal(txt.textContent, 'reconnecting in 1.0 s (attempt 2)');
});

test('while disconnected, what the server said is "unknown", not stale', () => {
  const s = new Session();
  s.opened();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: 4, scene: 'g', tick_hz: 1000 });
  s.apply({ type: 'telemetry', t: 1, stage: [0, 0, 1e-6], volts: 0, phase: 'approach', estimate: null });
  s.closed(1, 250);
  const f = statusFields(s.state);
  assert.deepEqual([f.role, f.client, f.lease.text, f.lease.cls, f.phase], ['unknown', 'unknown', 'unknown', 'unknown', 'unknown'],
    'not the last seen: operator, client 4, holding the lease, approach');
});

test('the instrument: the simulated AFM (an older server too), a real controller, read-only', () => {
  const s = new Session();
  assert.deepEqual(statusFields(s.state).instrument, { text: '–', title: 'The server has not said which instrument it drives yet', cls: '' }, 'before the welcome');
  s.opened();
  // An older server says nothing of its instrument: the simulated AFM at its tick rate.
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000 });
  assert.equal(statusFields(s.state).instrument.text, 'Simulated AFM · 1 kHz loop');
  s.apply({
    type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000,
    instrument: { backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: [] },
  });
  let f = statusFields(s.state).instrument;
  assert.equal(f.text, 'Nanonis 127.0.0.1:6501 · signals at 1 kHz · force held by the controller');
  assert.match(f.title, /^A real controller \(Nanonis 127\.0\.0\.1:6501\): the page shows its tip position and normal deflection, new readings at 1 kHz\./);
  assert.match(f.title, /Not offered from the page: push, scan, assemble, haptic handle; push with nanopush push --instrument, scan with nanopush scan --instrument\.$/);
  s.apply({
    type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'g', tick_hz: 1000,
    instrument: { backend: 'Nanonis 10.0.0.7:6501', feed_rate_hz: 2500, z_closed_locally: true, read_only: true, offers: [] },
  });
  f = statusFields(s.state).instrument;
  assert.equal(f.text, 'Nanonis 10.0.0.7:6501 · signals at 2.5 kHz · force held by the controller · read-only');
  assert.match(f.title, /Read-only: nothing that moves the tip or changes Z is sent to it\./);
  // While disconnected: the last known, said so.
  s.closed(1, 250);
  f = statusFields(s.state).instrument;
  assert.equal(f.text, 'Nanonis 10.0.0.7:6501 · signals at 2.5 kHz · force held by the controller · read-only');
  assert.equal(f.cls, 'unknown');
  assert.match(f.title, /^Last known, while disconnected\. A real controller/);
});
