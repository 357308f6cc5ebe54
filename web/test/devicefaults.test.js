// node --test: the haptic device's fault line (src/devicefaults.js) from /api/status's `haptic`
// object, the poller that fetches it (fake timers, fake fetches: one at a time, only while
// started, failures survived) and the haptic panel's device field fed by it (src/haptic.js,
// with stand-ins for its elements and the document).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { deviceFaultsLine, rateText, fetchStatus, StatusPoller, FAULT_SIDES } from '../src/devicefaults.js';
import { HapticPanel, DEVICE_FAULTS_PERIOD_MS } from '../src/haptic.js';

const ZERO = { bad_packets: 0, timeouts: 0, seq_gaps: 0, out_of_range: 0, watchdog_trips: 0, overruns: 0, losses: 0, reopens: 0 };
/** `/api/status`'s `haptic` with these counters (the others zero) and the server's `side`. */
const hap = (counts = {}, rate = 1000) => ({ link: 'up', rate_hz: rate, device_faults: { ...ZERO, ...counts, side: { ...FAULT_SIDES } } });

test('unknown faults are a dash: no haptic object, or nulls', () => {
  assert.deepEqual(deviceFaultsLine(null), { text: '–', cls: '' });
  assert.deepEqual(deviceFaultsLine(undefined), { text: '–', cls: '' });
  assert.deepEqual(deviceFaultsLine({ link: 'down', rate_hz: null, device_faults: null }), { text: '–', cls: '' }, 'before the first sample');
  assert.deepEqual(deviceFaultsLine({ link: 'off' }), { text: '–', cls: '' });
});

test('all counters zero: "faults: none", uncoloured', () => {
  assert.deepEqual(deviceFaultsLine(hap()), { text: '1 kHz · faults: none', cls: '' });
  assert.deepEqual(deviceFaultsLine(hap({}, null)), { text: 'faults: none', cls: '' }, 'no rate known: the faults alone');
});

test('device faults and a lost device reopened: one line, a warning', () => {
  assert.deepEqual(deviceFaultsLine(hap({ bad_packets: 2, timeouts: 1, losses: 1, reopens: 1 })), {
    text: '1 kHz · faults: device 3 (2 bad packets, 1 late answer) · bridge 0 · cable 1 lost, 1 reopened',
    cls: 'warn',
  });
});

test('singular and plural of every kind, each side with its total', () => {
  assert.equal(
    deviceFaultsLine(hap({ bad_packets: 1, timeouts: 2, seq_gaps: 1, out_of_range: 1, watchdog_trips: 1, overruns: 1 })).text,
    '1 kHz · faults: device 5 (1 bad packet, 2 late answers, 1 sequence gap, 1 state out of range) · bridge 2 (1 watchdog trip, 1 late cycle) · cable 0',
  );
  assert.equal(
    deviceFaultsLine(hap({ seq_gaps: 3, out_of_range: 4, watchdog_trips: 2, overruns: 5 }, 500)).text,
    '500 Hz · faults: device 7 (3 sequence gaps, 4 states out of range) · bridge 7 (2 watchdog trips, 5 late cycles) · cable 0',
  );
  assert.deepEqual(deviceFaultsLine(hap({ overruns: 1 })), { text: '1 kHz · faults: device 0 · bridge 1 (1 late cycle) · cable 0', cls: 'warn' });
});

test('a device lost and not reopened is bad; reopened again it is a warning', () => {
  assert.deepEqual(deviceFaultsLine(hap({ losses: 1 })), { text: '1 kHz · faults: device 0 · bridge 0 · cable 1 lost, 0 reopened', cls: 'bad' });
  assert.deepEqual(deviceFaultsLine(hap({ losses: 3, reopens: 2, timeouts: 1 }, 2500)), {
    text: '2.5 kHz · faults: device 1 (1 late answer) · bridge 0 · cable 3 lost, 2 reopened',
    cls: 'bad',
  });
  assert.equal(deviceFaultsLine(hap({ losses: 3, reopens: 3 })).cls, 'warn');
});

test('each kind\'s side: the server\'s `side`, else the known one', () => {
  const h = hap({ bad_packets: 1 });
  h.device_faults.side.bad_packets = 'cable';
  assert.equal(deviceFaultsLine(h).text, '1 kHz · faults: device 0 · bridge 0 · cable 1 bad packet, 0 lost, 0 reopened');
  const noSide = { rate_hz: 1000, device_faults: { ...ZERO, watchdog_trips: 2 } };
  assert.equal(deviceFaultsLine(noSide).text, '1 kHz · faults: device 0 · bridge 2 (2 watchdog trips) · cable 0');
  const newKind = { rate_hz: 1000, device_faults: { ...ZERO, brownouts: 1, side: { ...FAULT_SIDES, brownouts: 'power' } } };
  assert.deepEqual(deviceFaultsLine(newKind), { text: '1 kHz · faults: device 0 · bridge 0 · cable 0 · power 1 (1 brownouts)', cls: 'warn' });
});

test('the rate in words', () => {
  assert.deepEqual([1000, 999.6, 1000.4, 2500, 4000, 250, 12.3].map(rateText), ['1 kHz', '1000 Hz', '1 kHz', '2.5 kHz', '4 kHz', '250 Hz', '12 Hz']);
  assert.deepEqual([null, undefined, 0, -1, NaN, Infinity].map(rateText), [null, null, null, null, null, null]);
});

test('fetchStatus asks /api/status with the token, refuses an error status', async () => {
  const asked = [];
  const ok = async (url) => { asked.push(url); return { ok: true, json: async () => ({ haptic: null }) }; };
  assert.deepEqual(await fetchStatus({ search: '?token=a%2Bb' }, ok), { haptic: null });
  assert.deepEqual(await fetchStatus({ search: '' }, ok), { haptic: null });
  assert.deepEqual(asked, ['/api/status?token=a%2Bb', '/api/status']);
  await assert.rejects(fetchStatus({ search: '' }, async () => ({ ok: false, status: 403 })), /HTTP 403/);
});

/** Fake timers: `run(ms)` moves the clock on and fires what is due, in order. */
function fakeTimers() {
  let now = 0;
  let next = 1;
  const due = new Map();
  return {
    setTimeout: (fn, ms) => { due.set(next, { at: now + ms, fn }); return next++; },
    clearTimeout: (id) => { due.delete(id); },
    get pending() { return due.size; },
    run(ms) {
      const end = now + ms;
      for (;;) {
        let id = null;
        for (const [k, v] of due) if (v.at <= end && (id === null || v.at < due.get(id).at)) id = k;
        if (id === null) break;
        const v = due.get(id);
        now = v.at;
        due.delete(id);
        v.fn();
      }
      now = end;
    },
  };
}

/** Fetches that answer only when told: `answer(value)` / `fail(err)` settle the oldest one. */
function fakeFetches() {
  const waiting = [];
  const f = () => new Promise((resolve, reject) => waiting.push({ resolve, reject }));
  f.waiting = waiting;
  f.answer = async (v) => { waiting.shift().resolve(v); await flush(); };
  f.fail = async (e) => { waiting.shift().reject(e); await flush(); };
  return f;
}
const flush = () => new Promise((r) => setImmediate(r));

test('the poller: a period after each answer, one at a time, while started', async () => {
  const timers = fakeTimers();
  const fetches = fakeFetches();
  const got = [];
  const errors = [];
  const p = new StatusPoller({ fetchStatus: fetches, onStatus: (s) => got.push(s), onError: (e) => errors.push(e.message), periodMs: 2000, timers });
  assert.equal(p.fetches, 0, 'nothing before start');
  p.start();
  p.start();
  assert.equal(p.fetches, 1, 'one fetch at start, a second start does nothing');
  timers.run(10000);
  assert.equal(p.fetches, 1, 'a slow answer: no second fetch meanwhile');
  await fetches.answer({ n: 1 });
  assert.deepEqual(got, [{ n: 1 }]);
  timers.run(1999);
  assert.equal(p.fetches, 1);
  timers.run(1);
  assert.equal(p.fetches, 2, 'the next one 2 s after the answer');
  await fetches.fail(new Error('HTTP 502'));
  assert.deepEqual(errors, ['HTTP 502']);
  timers.run(2000);
  assert.equal(p.fetches, 3, 'a failure does not stop the polling');
  // Stopped with a fetch in flight: its answer is dropped, nothing more is fetched.
  p.stop();
  await fetches.answer({ n: 3 });
  timers.run(10000);
  assert.deepEqual([p.fetches, got.length, timers.pending], [3, 1, 0]);
  // Started again: at once; and a start while a fetch is in flight waits for it.
  p.start();
  assert.equal(p.fetches, 4);
  p.stop();
  p.start();
  assert.equal(p.fetches, 4, 'restarted with a fetch in flight: no second one');
  await fetches.answer({ n: 4 });
  assert.deepEqual(got.at(-1), { n: 4 });
  assert.equal(timers.pending, 1);
  timers.run(2000);
  assert.equal(p.fetches, 5);
  assert.equal(fetches.waiting.length, 1);
});

test('the poller survives a fetch and an onStatus that throw', async () => {
  const timers = fakeTimers();
  const errors = [];
  let n = 0;
  const p = new StatusPoller({
    fetchStatus: () => { n++; throw new Error('no network'); },
    onStatus: () => {},
    onError: (e) => errors.push(e.message),
    timers,
  });
  p.start();
  await flush();
  timers.run(2000);
  await flush();
  assert.deepEqual([n, errors], [2, ['no network', 'no network']]);
  p.stop();
  const q = new StatusPoller({ fetchStatus: async () => ({}), onStatus: () => { throw new Error('bad element'); }, onError: () => { throw new Error('worse'); }, timers });
  q.start();
  await flush();
  assert.equal(timers.pending, 1, 'still scheduled');
  q.stop();
});

/** The haptic panel with stand-ins for its elements, the frame scheduler and the document. */
function panel({ fetchStatus: fetchFn, timers }) {
  const el = () => ({ textContent: '–', className: '' });
  const fields = Object.fromEntries(['link', 'phase', 'engaged', 'handle', 'hand', 'tip', 'pc'].map((k) => [k, el()]));
  const listeners = [];
  const doc = { hidden: false, addEventListener: (type, fn) => listeners.push([type, fn]) };
  const els = { panel: { hidden: true }, plot: {}, fields, device: el() };
  const p = new HapticPanel(els, { register: () => ({ mark() {} }) }, { fetchStatus: fetchFn, doc, timers });
  const setHidden = (hidden) => {
    doc.hidden = hidden;
    for (const [type, fn] of listeners) if (type === 'visibilitychange') fn();
  };
  return { p, els, setHidden };
}

const telemetry = { link: 'up', phase: 'idle', handle_m: 0, force_n: 0, tip_force_n: 0, pc_active: false };

test('the panel\'s device row polls /api/status only while it is visible', async () => {
  const timers = fakeTimers();
  const fetches = fakeFetches();
  const { p, els, setHidden } = panel({ fetchStatus: fetches, timers });
  assert.equal(DEVICE_FAULTS_PERIOD_MS, 2000, 'every 2 s');
  timers.run(10000);
  assert.equal(fetches.waiting.length, 0, 'the panel is hidden (no haptic link yet): no fetch');
  p.update(null, null);
  assert.equal(fetches.waiting.length, 0, 'telemetry without haptic: still hidden, no fetch');
  p.update(1, telemetry);
  assert.equal(els.panel.hidden, false);
  assert.equal(fetches.waiting.length, 1, 'shown: fetched at once');
  p.update(1.1, telemetry);
  assert.equal(fetches.waiting.length, 1, 'more telemetry: no second fetch');
  await fetches.answer({ haptic: hap({ losses: 1 }) });
  assert.deepEqual([els.device.textContent, els.device.className], ['1 kHz · faults: device 0 · bridge 0 · cable 1 lost, 0 reopened', 'bad']);
  timers.run(2000);
  await fetches.answer({ haptic: hap() });
  assert.deepEqual([els.device.textContent, els.device.className], ['1 kHz · faults: none', '']);
  // A failed fetch: a dash, no exception, and the polling goes on.
  timers.run(2000);
  await fetches.fail(new Error('HTTP 500'));
  assert.deepEqual([els.device.textContent, els.device.className], ['–', '']);
  timers.run(2000);
  await fetches.answer({ haptic: { link: 'down', rate_hz: null, device_faults: null } });
  assert.equal(els.device.textContent, '–', 'no sample yet: a dash');
  // The page hidden (another tab): no fetch until it is visible again.
  setHidden(true);
  timers.run(20000);
  assert.equal(fetches.waiting.length, 0);
  assert.equal(timers.pending, 0);
  setHidden(false);
  assert.equal(fetches.waiting.length, 1, 'visible again: fetched at once');
  await fetches.answer({ haptic: hap({ timeouts: 1 }) });
  assert.deepEqual([els.device.textContent, els.device.className], ['1 kHz · faults: device 1 (1 late answer) · bridge 0 · cable 0', 'warn']);
  setHidden(true);
});

test('a panel with no way to fetch (the demo) keeps its dash, polls nothing', () => {
  const timers = fakeTimers();
  const { p, els } = panel({ fetchStatus: undefined, timers });
  p.update(1, telemetry);
  timers.run(10000);
  assert.deepEqual([els.panel.hidden, els.device.textContent, timers.pending], [false, '–', 0]);
});
