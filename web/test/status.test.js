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
  const els = { 'st-conn': el({ querySelector: () => txt }), 'st-role': el(), 'st-client': el(), 'st-lease': el(), 'st-phase': el(), 'st-lagged': el(), 'st-error': el() };
  const bar = new StatusBar((id) => els[id]);
  const s = new Session();
  s.opened();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'viewer', lease: 4, scene: 'g', tick_hz: 1000 });
  s.logError('client_socket', 'not connected');
  bar.render(s.state);
  assert.equal(els['st-conn'].className, 'conn-open');
  assert.equal(txt.textContent, 'connected');
  assert.equal(els['st-role'].textContent, 'viewer');
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
