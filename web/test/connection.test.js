// node --test: the connection (src/connection.js): URLs, backoff, and the Connection's
// reconnects and sends over a fake socket and fake timers.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { wsUrl, apiUrl, backoffMs, reconnectText, Connection, exchangeToken, signInNote } from '../src/connection.js';
import { Session } from '../src/session.js';
import { commands } from '../src/wire.js';

test('the WebSocket URL carries the page token; without one, a viewer', () => {
  assert.equal(wsUrl({ protocol: 'http:', host: '127.0.0.1:8080', search: '?token=abc%2Bd' }), 'ws://127.0.0.1:8080/ws?token=abc%2Bd');
  assert.equal(wsUrl({ protocol: 'http:', host: 'localhost:9', search: '' }), 'ws://localhost:9/ws');
  assert.equal(wsUrl({ protocol: 'https:', host: 'h', search: '?x=1&token=t' }), 'wss://h/ws?token=t');
});

test('reconnect backoff doubles from 0.25 s and stops at 2 s', () => {
  // A local instrument is tried at least every 2 s: a server back up is seen within 2 s.
  assert.deepEqual([1, 2, 3, 4, 5, 6, 7, 10].map((n) => backoffMs(n)), [250, 500, 1000, 2000, 2000, 2000, 2000, 2000]);
});

test('apiUrl passes the page token on to the JSON API', () => {
  assert.equal(apiUrl('/api/scene', { search: '?token=abc%2Bd' }), '/api/scene?token=abc%2Bd');
  assert.equal(apiUrl('/api/records/x.csv', { search: '' }), '/api/records/x.csv');
  assert.equal(apiUrl('/api/records?a=1', { search: '?token=t' }), '/api/records?a=1&token=t');
});

/** Fake timers: `run(ms)` moves the clock on and fires what is due, in order. */
function fakeTimers() {
  let now = 0;
  let next = 1;
  const due = new Map(); // id → {at, fn, every}
  const t = {
    now: () => now,
    setTimeout: (fn, ms) => { due.set(next, { at: now + ms, fn }); return next++; },
    clearTimeout: (id) => { due.delete(id); },
    setInterval: (fn, ms) => { due.set(next, { at: now + ms, fn, every: ms }); return next++; },
    clearInterval: (id) => { due.delete(id); },
    get pending() { return due.size; },
    run(ms) {
      const end = now + ms;
      for (;;) {
        let id = null;
        for (const [k, v] of due) if (v.at <= end && (id === null || v.at < due.get(id).at)) id = k;
        if (id === null) break;
        const v = due.get(id);
        now = v.at;
        if (v.every) v.at += v.every;
        else due.delete(id);
        v.fn();
      }
      now = end;
    },
  };
  return t;
}

class FakeSocket {
  constructor(url) {
    this.url = url;
    this.readyState = 0;
    this.sent = [];
  }

  send(text) {
    this.sent.push(text);
  }

  open() {
    this.readyState = 1;
    this.onopen();
  }

  close(code = 1006) {
    this.readyState = 3;
    this.onclose({ code, reason: '' });
  }
}

function harness({ fail = 0 } = {}) {
  const session = new Session();
  const timers = fakeTimers();
  const sockets = [];
  const seen = [];
  let failures = fail;
  const conn = new Connection(session, {
    url: 'ws://h/ws?token=t',
    open: (url) => {
      if (failures-- > 0) throw new Error('refused');
      const s = new FakeSocket(url);
      sockets.push(s);
      return s;
    },
    onOpen: () => seen.push('open'),
    onMessage: (d) => seen.push(`msg ${d}`),
    onClose: (ev) => seen.push(`close ${ev.code} lease=${session.hasLease}`),
    onCountdown: (text) => seen.push(text),
    onSend: (m) => seen.push(`send #${m.id}`),
    onChange: () => seen.push(`change ${session.state.connection}`),
    timers,
    now: timers.now,
  });
  return { session, timers, sockets, seen, conn };
}

test('a connection opens, passes messages on, sends commands with ids', () => {
  const h = harness();
  h.conn.connect();
  assert.equal(h.session.state.connection, 'connecting');
  assert.equal(h.sockets.length, 1);
  assert.equal(h.sockets[0].url, 'ws://h/ws?token=t');
  assert.equal(h.sockets[0].binaryType, 'arraybuffer');
  assert.equal(h.conn.send(commands.takeLease()), null, 'not open yet: not sent');
  assert.equal(h.session.state.lastError.code, 'client_socket');
  h.sockets[0].open();
  assert.equal(h.session.state.connection, 'open');
  h.sockets[0].onmessage({ data: '{"type":"ping"}' });
  const m = h.conn.send(commands.takeLease());
  assert.deepEqual(m, { type: 'take_lease', id: 1 }, 'numbered by the Session');
  assert.deepEqual(h.sockets[0].sent, ['{"type":"take_lease","id":1}']);
  assert.deepEqual(h.seen, ['change connecting', 'change connecting', 'open', 'msg {"type":"ping"}', 'send #1']);
});

test('acks go unnumbered, at most every 100 ms, the newest read going last', () => {
  const h = harness();
  h.conn.connect();
  h.conn.ack(5);
  assert.deepEqual(h.sockets[0].sent, [], 'not open yet: not sent');
  h.sockets[0].open();
  h.conn.ack(7);
  assert.deepEqual(h.sockets[0].sent, ['{"type":"ack","seq":7}'], 'the first at once');
  assert.ok(!h.seen.some((s) => s.startsWith('send')), 'not a command the replies wait for');
  assert.equal(h.conn.send(commands.ping()).id, 1, 'the next command is still #1');
  h.sockets[0].sent.length = 0;
  // Frames read within the 100 ms: one ack, of the newest, when they are over.
  h.timers.run(30);
  h.conn.ack(8);
  h.timers.run(30);
  h.conn.ack(9);
  assert.deepEqual(h.sockets[0].sent, []);
  h.timers.run(40);
  assert.deepEqual(h.sockets[0].sent, ['{"type":"ack","seq":9}'], 'at 100 ms: the newest');
  h.conn.ack(9);
  h.timers.run(500);
  assert.deepEqual(h.sockets[0].sent, ['{"type":"ack","seq":9}'], 'nothing new: nothing sent');
  // A new socket (a restarted server counts from 1 again): acknowledged from its first frame.
  h.sockets[0].close();
  h.timers.run(1000);
  h.sockets[1].open();
  h.conn.ack(1);
  assert.deepEqual(h.sockets[1].sent, ['{"type":"ack","seq":1}']);
});

test('a closed connection reconnects with backoff, counting down', () => {
  const h = harness();
  h.conn.connect();
  h.sockets[0].open();
  h.session.apply({ type: 'welcome', version: 1, client: 3, role: 'operator', lease: 3, scene: 's', tick_hz: 1000 });
  h.seen.length = 0;
  h.sockets[0].close(1006);
  // onClose hears it while the Session still knows the lease was held.
  assert.deepEqual(h.seen, ['close 1006 lease=true', 'change closed', 'reconnecting in 0.3 s (attempt 1)']);
  assert.deepEqual(h.session.state.reconnect, { attempt: 1, delayMs: 250 });
  assert.equal(h.session.state.client, null);
  h.seen.length = 0;
  h.timers.run(249);
  assert.equal(h.sockets.length, 1, 'not before 0.25 s');
  assert.deepEqual(h.seen, [], 'the countdown ticks every 250 ms');
  h.timers.run(1);
  assert.equal(h.sockets.length, 2);
  assert.deepEqual(h.seen.slice(-2), ['reconnecting in 0.0 s (attempt 1)', 'change connecting']);
  assert.equal(reconnectText(1960, 6), 'reconnecting in 2.0 s (attempt 6)');
  // Closed again before it opened: 0.5 s, then 1 s.
  h.sockets[1].close();
  assert.equal(h.session.state.reconnect.delayMs, 500);
  h.timers.run(500);
  h.sockets[2].close();
  assert.equal(h.session.state.reconnect.delayMs, 1000);
  h.timers.run(1000);
  assert.equal(h.sockets.length, 4);
  h.sockets[3].open();
  assert.equal(h.conn.attempt, 0);
  h.sockets[3].close();
  assert.equal(h.session.state.reconnect.delayMs, 250, 'counted from 1 again after an open');
  // A socket that closes after being replaced is ignored.
  h.timers.run(250);
  assert.equal(h.sockets.length, 5);
  h.sockets[3].onclose({ code: 1000, reason: '' });
  assert.equal(h.conn.attempt, 1);
  assert.equal(h.session.state.reconnect, null);
  assert.equal(h.session.state.connection, 'connecting');
});

test('a socket that cannot be made is logged and retried', () => {
  const h = harness({ fail: 2 });
  h.conn.connect();
  assert.equal(h.session.state.lastError.message, 'refused');
  assert.equal(h.session.state.reconnect.attempt, 1);
  h.timers.run(500);
  assert.equal(h.session.state.reconnect.attempt, 2);
  h.timers.run(1000);
  assert.equal(h.sockets.length, 1);
  assert.equal(h.timers.pending, 1, 'no countdown or retry left running: only the new socket\'s silence watchdog');
});

test('a socket made asynchronously (the demo) is attached when it comes', async () => {
  const session = new Session();
  const s = new FakeSocket('u');
  const conn = new Connection(session, { url: 'u', open: () => Promise.resolve(s), timers: fakeTimers() });
  conn.connect();
  assert.equal(conn.ws, null);
  await null;
  await null;
  assert.equal(conn.ws, s);
  s.open();
  assert.equal(session.state.connection, 'open');
});

test('onClose tells a refused reconnect from a connection that closed', () => {
  const session = new Session();
  const timers = fakeTimers();
  const sockets = [];
  const closes = [];
  const conn = new Connection(session, {
    url: 'ws://h/ws',
    open: (url) => {
      const s = new FakeSocket(url);
      sockets.push(s);
      return s;
    },
    onClose: (ev, info) => closes.push(info?.wasOpen),
    timers,
    now: timers.now,
  });
  conn.connect();
  sockets[0].open();
  sockets[0].close();
  // The server stays down: each attempt is refused (closed before it opened).
  for (let i = 1; i <= 5; i++) {
    timers.run(2000);
    sockets[i].close();
  }
  assert.deepEqual(closes, [true, false, false, false, false, false], 'one "connection closed", five refused attempts');
});

test('a silent socket or a handshake that never ends is given up, retried', () => {
  const session = new Session();
  const timers = fakeTimers();
  const sockets = [];
  const closes = [];
  const conn = new Connection(session, {
    url: 'ws://h/ws',
    open: (url) => {
      const s = new FakeSocket(url);
      s.close = () => { s.readyState = 3; s.closedByPage = true; };
      sockets.push(s);
      return s;
    },
    onClose: (ev, info) => closes.push([ev.reason, info.wasOpen]),
    timers,
    now: timers.now,
  });
  conn.connect();
  sockets[0].open();
  // Messages keep it alive.
  for (let i = 0; i < 10; i++) {
    timers.run(1000);
    sockets[0].onmessage({ data: '{"type":"telemetry"}' });
  }
  assert.deepEqual(closes, []);
  assert.equal(session.state.connection, 'open');
  // Then nothing (a hung server, or a network that drops packets without closing): given up
  // within a second of 5 s.
  timers.run(5000);
  assert.equal(closes.length, 0, 'not before 5 s');
  timers.run(1000);
  assert.deepEqual(closes, [['no word from the server for 5 s', true]]);
  assert.equal(sockets[0].closedByPage, true);
  assert.equal(session.state.connection, 'closed');
  // A late close event of the dropped socket changes nothing.
  sockets[0].onclose({ code: 1006, reason: '' });
  assert.equal(closes.length, 1);
  // The next attempt's handshake never finishes: dropped too, and tried again.
  timers.run(250);
  assert.equal(sockets.length, 2);
  timers.run(6000);
  assert.equal(sockets[1].closedByPage, true);
  assert.deepEqual(closes[1], ['no word from the server for 5 s', false]);
  timers.run(500);
  assert.equal(sockets.length, 3);
  sockets[2].open();
  assert.equal(session.state.connection, 'open');
});

test('a socket promised and refused is logged and retried, not thrown', async () => {
  const session = new Session();
  const timers = fakeTimers();
  let tries = 0;
  // The demo's module did not load: no unhandled rejection, an error logged and a retry.
  const conn = new Connection(session, { url: 'u', open: () => { tries++; return Promise.reject(new Error('no module')); }, timers, now: timers.now });
  conn.connect();
  await new Promise((r) => setImmediate(r));
  assert.equal(session.state.lastError.message, 'no module');
  assert.equal(session.state.connection, 'closed');
  timers.run(250);
  assert.equal(tries, 2);
  await new Promise((r) => setImmediate(r));
});

test('the URL token is exchanged for the cookie and leaves the address bar', async () => {
  const calls = [];
  const replaced = [];
  const fetchFn = async (url, init) => {
    calls.push({ url, init });
    return { ok: true, json: async () => ({ name: 'alice', role: 'operator' }) };
  };
  const history = { state: null, replaceState: (s, t, url) => replaced.push(url) };
  const loc = { search: '?view=monitor&token=npt_ab_cd', pathname: '/', hash: '' };
  const me = await exchangeToken(loc, { fetchFn, history });
  assert.deepEqual(me, { name: 'alice', role: 'operator' });
  assert.equal(calls.length, 1);
  assert.equal(calls[0].url, '/api/session');
  assert.equal(calls[0].init.method, 'POST');
  assert.equal(calls[0].init.headers.Authorization, 'Bearer npt_ab_cd');
  assert.deepEqual(replaced, ['/?view=monitor'], 'the token gone, the other parameters kept');
  // Refused: the token stays (the connection carries it and says why); no token: nothing asked.
  const refused = async () => ({ ok: false, json: async () => ({}) });
  assert.equal(await exchangeToken(loc, { fetchFn: refused, history }), null);
  assert.equal(replaced.length, 1);
  assert.equal(await exchangeToken({ search: '', pathname: '/', hash: '' }, { fetchFn, history }), null);
  assert.equal(calls.length, 1);
});

test('signInNote: how to sign in when the server does not know this person', async () => {
  const answer = (status, text = '') => async () => ({ status, ok: status < 300, text: async () => text });
  assert.match(await signInNote({ fetchFn: answer(401) }), /needs your token.*\?token=/);
  assert.match(await signInNote({ fetchFn: answer(429, 'too many failed attempts from 10.0.0.9; try again in 5 s') }), /too many failed attempts from 10\.0\.0\.9/);
  assert.equal(await signInNote({ fetchFn: answer(200) }), null, 'known: nothing to say');
  assert.equal(await signInNote({ fetchFn: async () => { throw new Error('offline'); } }), null, 'cannot be asked: nothing to say');
});
