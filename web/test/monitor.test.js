// node --test: the monitoring view's tiles from /api/status, the haptic device's faults among them
// (src/monitor.js; its DOM is not built).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { statusTiles, alertsOf, downText, runLine } from '../src/monitor.js';

test('the tiles of a busy instrument: overruns, an engaged haptic link', () => {
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
    ['m-alerts', '2 loop overruns', 'bad'],
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
  assert.deepEqual(statusTiles({ phase: 'contact_search', loop: {} }).find((t) => t[0] === 'm-phase'), ['m-phase', 'finding the particle\'s edge', ''], 'a phase in words');
  assert.deepEqual(statusTiles({ loop: {}, haptic: { link: 'down' } }).find((t) => t[0] === 'm-haptic'), ['m-haptic', 'down', 'bad']);
  const lost = { loop: {}, haptic: { link: 'down', rate_hz: 1000, device_faults: { bad_packets: 0, timeouts: 0, seq_gaps: 0, out_of_range: 0, watchdog_trips: 0, overruns: 0, losses: 2, reopens: 1 } } };
  assert.deepEqual(statusTiles(lost).find((t) => t[0] === 'm-hapdev'), ['m-hapdev', '1 kHz · faults: device 0 · bridge 0 · cable 2 lost, 1 reopened', 'bad']);
});

test('alerts: "none" when healthy, else each in words', () => {
  assert.deepEqual(alertsOf({ loop: { overruns: 0 }, haptic: { link: 'up' }, dropped_frames: 0 }), []);
  assert.deepEqual(alertsOf({ loop: { overruns: 3 }, haptic: { link: 'down', engaged: true, fault: 'link_lost' }, dropped_frames: 7 }),
    ['3 loop overruns', 'haptic link down while engaged', 'haptic fault: link_lost', '7 telemetry frames dropped'],
    'overruns, a lost haptic link (worse while engaged), faults, dropped frames');
  const t = new Map(statusTiles({ loop: { overruns: 0 }, haptic: { link: 'up', link_downs: 2 }, uptime_s: 600, started_unix_ms: Date.UTC(2026, 0, 1, 12, 0, 0) }).map(([id, text, cls]) => [id, [text, cls]]));
  assert.deepEqual(t.get('m-alerts'), ['none', 'good']);
  assert.equal(t.get('m-haptic')[0], 'up, 2 link losses');
  assert.match(t.get('m-uptime')[0], /^\d\d:\d\d:\d\d \(10 min\)$/);
  assert.deepEqual(statusTiles({ loop: { period_error_p99_bound_s: 0.1 } }).find((x) => x[0] === 'm-jitter'), ['m-jitter', '≤ 100 ms', 'warn']);
});

test('the down banner names the time; a history line reads as the page\'s', () => {
  // The browser's "Failed to fetch" is no word for people: the server cannot be reached.
  assert.match(downText(Date.UTC(2026, 0, 1, 12, 0, 0), 'Failed to fetch'), /^server down since \d\d:\d\d:\d\d \(it cannot be reached\); what is shown below is from before$/);
  assert.match(downText(Date.UTC(2026, 0, 1, 12, 0, 0), 'no answer within 3 s'), /\(no answer within 3 s\)/);
  const l = runLine({ record: 'push-1-r1-p1.json', modified: 1767268800, run: 1, particle: 1, outcome: 'stopped', failure: 'stopped: the lease holder disconnected', estimate: [1e-6, 2e-6] });
  assert.match(l, /^\d\d:\d\d:\d\d push of #1 stopped: the lease holder disconnected, particle left at \(1\.00, 2\.00\) µm \(record push-1-r1-p1\.json\)$/);
  // Who ran it, where the record says.
  assert.match(runLine({ record: 'push-1-r2-p1.json', modified: 1767268800, run: 2, particle: 1, outcome: 'ok', failure: null, estimate: [1e-6, 2e-6], person: 'alice' }), / — alice$/);
});
