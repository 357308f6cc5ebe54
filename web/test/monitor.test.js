// node --test: the monitoring view's tiles from /api/status, the haptic device's faults among them
// (src/monitor.js; its DOM is not built).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { statusTiles } from '../src/monitor.js';

test('the tiles of a busy instrument with overruns and an engaged haptic link', () => {
  const tiles = statusTiles({
    scene: 'gold-latex', phase: 'pushing', busy: true, clients: 3, lease: 4, uptime_s: 125.7,
    loop: { ticks: 5000, overruns: 2, realtime: true, period_error_p99_bound_s: 4.2e-5 },
    haptic: {
      link: 'up', engaged: true, rate_hz: 1000,
      device_faults: { bad_packets: 2, timeouts: 0, seq_gaps: 0, out_of_range: 0, watchdog_trips: 1, overruns: 0, losses: 0, reopens: 0, side: { bad_packets: 'device', timeouts: 'device', seq_gaps: 'device', out_of_range: 'device', watchdog_trips: 'bridge', overruns: 'bridge', losses: 'cable', reopens: 'cable' } },
    },
  });
  assert.deepEqual(tiles, [
    ['m-scene', '· gold-latex', ''],
    ['m-phase', 'pushing (busy)', ''],
    ['m-loop', '5000 ticks, 2 overruns, real-time', 'warn'],
    ['m-jitter', '≤ 42 µs', ''],
    ['m-haptic', 'up, engaged', ''],
    ['m-clients', '3', ''],
    ['m-lease', 'client 4', ''],
    ['m-uptime', '2 min 5 s', ''],
    ['m-hapdev', '1 kHz · faults: device 2 (2 bad packets) · bridge 1 (1 watchdog trip) · cable 0', 'warn'],
  ]);
});

test('an idle instrument with no haptic link, no p99 yet and a free lease', () => {
  const m = new Map(statusTiles({ scene: 's', phase: 'idle', clients: 1, lease: null, uptime_s: 3, loop: { ticks: 10, overruns: 0, realtime: false } }).map(([id, text, cls]) => [id, [text, cls]]));
  assert.deepEqual(m.get('m-loop'), ['10 ticks, no overruns, not real-time', 'good']);
  assert.deepEqual(m.get('m-jitter'), ['–', '']);
  assert.deepEqual(m.get('m-haptic'), ['off', '']);
  assert.deepEqual(m.get('m-hapdev'), ['–', ''], 'no haptic link: no device faults');
  assert.deepEqual(m.get('m-lease'), ['free', '']);
  assert.equal(m.get('m-phase')[0], 'idle');
  assert.deepEqual(statusTiles({ loop: {}, haptic: { link: 'down' } }).find((t) => t[0] === 'm-haptic'), ['m-haptic', 'down', 'bad']);
  const lost = { loop: {}, haptic: { link: 'down', rate_hz: 1000, device_faults: { bad_packets: 0, timeouts: 0, seq_gaps: 0, out_of_range: 0, watchdog_trips: 0, overruns: 0, losses: 2, reopens: 1 } } };
  assert.deepEqual(statusTiles(lost).find((t) => t[0] === 'm-hapdev'), ['m-hapdev', '1 kHz · faults: device 0 · bridge 0 · cable 2 lost, 1 reopened', 'bad']);
});
