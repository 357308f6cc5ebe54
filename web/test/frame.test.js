// node --test: the page's one animation-frame loop (src/frame.js) with a fake
// requestAnimationFrame and a fake clock: what is drawn in which frame.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { FrameScheduler, livePeriodMs, livePeriodFor, liveSlotMs, SLOW_DRAW_MS } from '../src/frame.js';

/** A scheduler whose frames the test runs: `frame(t)` runs the pending callback at time t. */
function fake() {
  let pending = null;
  let requests = 0;
  const clock = { now: 0 };
  const s = new FrameScheduler({
    requestFrame: (cb) => {
      assert.equal(pending, null, 'one frame requested at a time');
      pending = cb;
      requests++;
    },
    clock: () => clock.now,
  });
  return {
    s,
    clock,
    get requests() { return requests; },
    frame(t) {
      assert.ok(pending, 'a frame was requested');
      const cb = pending;
      pending = null;
      clock.now = t;
      cb(t);
    },
  };
}

test('live views: every frame while frames are quick, else 3 frame times', () => {
  assert.equal(livePeriodMs(16.7), 0);
  assert.equal(livePeriodMs(40), 0, 'frames of up to 40 ms are quick');
  assert.equal(livePeriodMs(41), 250, 'at least 250 ms');
  assert.equal(livePeriodMs(100), 300);
  assert.equal(livePeriodMs(250), 750);
  assert.equal(livePeriodMs(400), 1000);
  assert.equal(livePeriodMs(2000), 1000, 'at most 1 s');
});

test('a software renderer\'s live views change in slots: 100 ms, 200 with 3D', () => {
  assert.equal(liveSlotMs(true), 100);
  assert.equal(liveSlotMs(true, true), 200, 'the 3D view shown doubles a frame\'s cost');
  assert.equal(liveSlotMs(false, true), 0, 'a GPU: every frame');
  assert.equal(livePeriodFor(16.7, 100), 100, 'quick frames: one slot');
  assert.equal(livePeriodFor(100, 100), 300, '300 ms: whole slots');
  assert.equal(livePeriodFor(41, 200), 400, '250 ms rounded up to whole slots');
  assert.equal(livePeriodFor(16.7, 0), 0);
  assert.equal(livePeriodFor(41, 0), 250, 'a GPU\'s slow frames as before');
});

test('views aligned to slots of 100 and 200 ms change in the same frames', () => {
  const f = fake();
  const frames = { tip: [], text: [] };
  const tip = f.s.register('tip', (p, now) => frames.tip.push(now), { period: 100, aligned: true });
  const text = f.s.register('text', (p, now) => frames.text.push(now), { period: 200, aligned: true });
  f.s.start();
  for (let t = 1000; t < 1600; t += 16) {
    tip.mark();
    text.mark();
    f.frame(t);
  }
  // Frames every 16 ms: the first of each slot.
  assert.deepEqual(frames.tip, [1000, 1112, 1208, 1304, 1400, 1512]);
  assert.deepEqual(frames.text, [1000, 1208, 1400], 'each in a frame the tip changes in too');
});

test('one loop: a marked view is drawn once in the next frame, with its parts', () => {
  const f = fake();
  const drawn = [];
  const a = f.s.register('a', (parts, now) => drawn.push(['a', [...parts].sort(), now]));
  const b = f.s.register('b', (parts) => drawn.push(['b', [...parts]]));
  f.s.start();
  f.s.start(); // once
  assert.equal(f.requests, 1);
  f.frame(16);
  assert.deepEqual(drawn, [], 'nothing dirty, nothing drawn');
  assert.equal(f.requests, 2, 'the loop runs on, dirty or not');
  a.mark('tip');
  a.mark('charts');
  a.mark('tip');
  assert.deepEqual(drawn, [], 'not drawn on a mark');
  f.frame(33);
  assert.deepEqual(drawn, [['a', ['charts', 'tip'], 33]], 'three marks, one draw, with the parts marked');
  assert.equal(a.frames, 1);
  assert.equal(b.frames, 0);
  f.frame(50);
  assert.equal(drawn.length, 1, 'drawn once: the mark was used up');
  b.mark();
  a.mark();
  f.frame(66);
  assert.deepEqual(drawn.slice(1), [['a', [], 66], ['b', []]], 'in the order they registered');
  assert.equal(f.s.frames, 4);
});

test('a view marked during a frame\'s draws: this frame if later, else the next', () => {
  const f = fake();
  const log = [];
  let late;
  const first = f.s.register('first', () => {
    log.push('first');
    late.mark();
  });
  late = f.s.register('late', () => {
    log.push('late');
    first.mark();
  });
  f.s.start();
  first.mark();
  f.frame(16);
  assert.deepEqual(log, ['first', 'late'], 'marked by an earlier view: drawn in the same frame');
  f.frame(33);
  assert.deepEqual(log, ['first', 'late', 'first', 'late'], 'marked by a later view: drawn in the next');
});

test('frameInterval follows the frames\' spacing, smoothed, gaps capped', () => {
  const f = fake();
  f.s.start();
  assert.equal(f.s.frameInterval, 16.7);
  f.frame(1000);
  assert.equal(f.s.frameInterval, 16.7, 'the first frame has no interval');
  f.frame(1100);
  assert.ok(Math.abs(f.s.frameInterval - (16.7 + 0.2 * (100 - 16.7))) < 1e-9, `smoothed by 0.2: ${f.s.frameInterval}`);
  for (let t = 1200; t <= 9000; t += 100) f.frame(t);
  assert.ok(Math.abs(f.s.frameInterval - 100) < 0.01, `${f.s.frameInterval}`);
  f.frame(19000);
  assert.ok(Math.abs(f.s.frameInterval - (100 + 0.2 * (2000 - 100))) < 0.01, `a 10 s gap counted as 2 s: ${f.s.frameInterval}`);
});

test('a period spaces the draws: live views at livePeriodMs(frame interval)', () => {
  const f = fake();
  const at = [];
  const live = f.s.register('live', (parts, now) => at.push(now), { period: () => livePeriodMs(f.s.frameInterval) });
  f.s.start();
  // Quick frames (16 ms): drawn every frame it is marked.
  for (let t = 16; t <= 160; t += 16) {
    live.mark('tip');
    f.frame(t);
  }
  assert.equal(at.length, 10);
  // Slow frames (100 ms apart): once frameInterval passes 40 ms, at least 250 ms apart (3 × the interval).
  at.length = 0;
  for (let t = 260; t <= 6000; t += 100) {
    live.mark('tip');
    f.frame(t);
  }
  const gaps = at.slice(1).map((t, i) => t - at[i]);
  assert.ok(gaps.slice(-5).every((g) => g === 300), `late gaps ${gaps.slice(-5)}`);
  assert.ok(gaps.every((g) => g === 100 || g >= 250), `${gaps}`);
  assert.equal(at.at(-1), 5960);
  live.mark('tip');
  f.frame(6060);
  assert.equal(at.at(-1), 5960, 'not yet: 100 ms after the last draw');
  assert.ok(live.dirty, 'a mark waiting for its period stays');
  f.frame(6160);
  f.frame(6260);
  assert.equal(at.at(-1), 6260);
  // A fixed period (the plots: 120 ms) with 16 ms frames: every 8th frame (128 ms).
  const g = fake();
  const drawn = [];
  const charts = g.s.register('charts', (p, now) => drawn.push(now), { period: 120 });
  g.s.start();
  for (let t = 1000; t <= 1512; t += 16) {
    charts.mark();
    g.frame(t);
  }
  assert.deepEqual(drawn, [1000, 1128, 1256, 1384, 1512]);
});

test('after a slow draw a view waits as long as it took; quick ones do not', () => {
  const f = fake();
  let cost = 30;
  const drawn = [];
  const v3d = f.s.register('view3d', (p, now) => {
    drawn.push(now);
    f.clock.now += cost; // the draw takes `cost` ms of main thread
  }, { waitAfterSlow: true });
  const other = f.s.register('image2d', (p, now) => drawn.push(`other ${now}`));
  f.s.start();
  v3d.mark();
  f.frame(1000); // drawn, took 30 ms: not before 1030 + 30 = 1060
  assert.equal(v3d.ms, 30);
  assert.equal(v3d.notBefore, 1060);
  assert.equal(v3d.totalMs, 30, 'its draws\' time, summed');
  v3d.mark();
  other.mark();
  f.frame(1033);
  f.frame(1050);
  assert.deepEqual(drawn, [1000, 'other 1033'], 'the slow view waits; the other is drawn');
  f.frame(1066);
  assert.deepEqual(drawn, [1000, 'other 1033', 1066]);
  assert.equal(v3d.totalMs, 60, 'two draws of 30 ms');
  // A quick draw (≤ SLOW_DRAW_MS): no wait.
  cost = SLOW_DRAW_MS;
  v3d.mark();
  f.frame(1200);
  v3d.mark();
  f.frame(1216);
  assert.deepEqual(drawn.slice(-2), [1200, 1216]);
  assert.equal(v3d.frames, 4);
  // Without waitAfterSlow, a slow view is drawn again in the next frame.
  const g = fake();
  const slow = g.s.register('slow', () => { g.clock.now += 50; });
  g.s.start();
  slow.mark();
  g.frame(100);
  slow.mark();
  g.frame(116);
  assert.equal(slow.frames, 2);
});

test('a draw that throws is reported; the other views and the loop go on', () => {
  const errors = [];
  let pending = null;
  const s = new FrameScheduler({ requestFrame: (cb) => { pending = cb; }, clock: () => 0, onError: (e) => errors.push(e.message) });
  const bad = s.register('bad', () => { throw new Error('boom'); });
  let good = 0;
  const ok = s.register('ok', () => { good++; });
  s.start();
  bad.mark();
  ok.mark();
  const cb = pending;
  pending = null;
  cb(16);
  assert.deepEqual(errors, ['boom']);
  assert.equal(good, 1);
  assert.ok(pending, 'the next frame was requested');
  assert.equal(bad.dirty, false);
});

test('aligned views draw in the same frames: the first of each period\'s slot', () => {
  // A software renderer pays for a whole frame whenever anything on screen changes: the tip
  // (every 50 ms), the map (100 ms) and the plots (200 ms) change in the same frames, and the
  // frames between stay clean.
  const f = fake();
  const drawn = { tip: [], map: [], plots: [] };
  const tip = f.s.register('tip', (p, now) => drawn.tip.push(now), { period: 50, aligned: true });
  const map = f.s.register('map', (p, now) => drawn.map.push(now), { period: 100, aligned: true });
  const plots = f.s.register('plots', (p, now) => drawn.plots.push(now), { period: 200, aligned: true });
  f.s.start();
  for (let t = 1000; t < 1400; t += 16) {
    tip.mark();
    map.mark();
    plots.mark();
    f.frame(t);
  }
  // 16 ms frames: 1000, 1016, … 1064 (the first in [1050, 1100)), 1112, …
  assert.deepEqual(drawn.tip, [1000, 1064, 1112, 1160, 1208, 1256, 1304, 1352]);
  assert.deepEqual(drawn.map, [1000, 1112, 1208, 1304]);
  assert.deepEqual(drawn.plots, [1000, 1208]);
  const every = new Set(drawn.tip);
  assert.ok([...drawn.map, ...drawn.plots].every((t) => every.has(t)), 'the slower views draw only in frames the tip draws in');
  // A zero period is every frame, aligned or not.
  const g = fake();
  const n = [];
  const v = g.s.register('v', (p, now) => n.push(now), { period: () => 0, aligned: true });
  g.s.start();
  for (const t of [16, 32, 48]) {
    v.mark();
    g.frame(t);
  }
  assert.deepEqual(n, [16, 32, 48]);
});
