// node --test: the map layer's geometry and picking (src/mapoverlay.js; its SVG is not built).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { toPx, toStage, nearestParticle, stepCursor, TrailBuffer, foundParticles, ringPx, arrowHead, MIN_RING_PX } from '../src/mapoverlay.js';

const g = { x: 50, y: 10, w: 400, h: 200 };
const e = { x_offset: 30e-6, y_offset: 20e-6, x_real: 20e-6, y_real: 10e-6 };

test('stage metres to the image\'s pixels and back: y up, origin at the scan', () => {
  assert.deepEqual(toPx(g, e, 30e-6, 20e-6), [50, 210], 'the lower left corner');
  assert.deepEqual(toPx(g, e, 50e-6, 30e-6).map((v) => Math.round(v * 1e6) / 1e6), [450, 10], 'the upper right');
  const [x, y] = toStage(g, e, 150, 110);
  assert.ok(Math.abs(x - 35e-6) < 1e-15 && Math.abs(y - 25e-6) < 1e-15, `${x} ${y}`);
});

test('a pick takes the nearest particle whose ring holds it; a minimum ring', () => {
  const ps = [{ id: 1, x: 40e-6, y: 25e-6, radius: 0.5e-6 }, { id: 2, x: 41e-6, y: 25e-6, radius: 0.7e-6 }, { id: 3, x: 45e-6, y: 25e-6, radius: 7e-9 }];
  assert.equal(nearestParticle(ps, 40.6e-6, 25e-6, 0.1e-6).id, 2, 'inside both rings: the nearer centre');
  assert.equal(nearestParticle(ps, 40.2e-6, 25e-6, 0.1e-6).id, 1);
  assert.equal(nearestParticle(ps, 45.2e-6, 25e-6, 0.1e-6), null, 'a 7 nm particle 0.2 µm away, 0.1 µm minimum ring');
  assert.equal(nearestParticle(ps, 45.2e-6, 25e-6, 0.3e-6).id, 3, '… found within an 8 px ring');
  assert.equal(nearestParticle(ps, 35e-6, 22e-6, 0.1e-6), null);
});

test('the keyboard cursor steps across the image, further with Shift', () => {
  const c = stepCursor([40e-6, 25e-6], 'ArrowRight', false, e);
  assert.ok(Math.abs(c[0] - 40.2e-6) < 1e-15 && c[1] === 25e-6, '1 % of the 20 µm image');
  const u = stepCursor([40e-6, 25e-6], 'ArrowUp', true, e);
  assert.ok(Math.abs(u[1] - 26e-6) < 1e-15, 'up is +y; with Shift 10 % of the 10 µm image');
  assert.deepEqual(stepCursor([30e-6, 20e-6], 'ArrowLeft', true, e), [30e-6, 20e-6], 'clamped at the edge');
  assert.equal(stepCursor([30e-6, 20e-6], 'Enter', false, e), null);
});

test('the push trail: a point per pixel the tip moved, at most its length', () => {
  const t = new TrailBuffer(3);
  assert.equal(t.add(0, 0, 1e-7), true);
  assert.equal(t.add(0.5e-7, 0, 1e-7), false, 'less than a pixel');
  for (let k = 1; k <= 4; k++) t.add(k * 1e-6, 0, 1e-7);
  assert.deepEqual(t.pts.map((p) => p[0]), [2e-6, 3e-6, 4e-6]);
  t.clear();
  assert.equal(t.pts.length, 0);
});

test('a scan record\'s particles are kept only when they are numbers', () => {
  // A hand-edited or damaged summary must draw no NaN rings and raise no console errors.
  const good = { x: 1e-6, y: 2e-6, radius: 5e-7 };
  assert.deepEqual(foundParticles([good, { x: 'a', y: 2e-6, radius: 5e-7 }, { x: 1e-6, y: null, radius: 1 }, { x: 1, y: 1, radius: -1 }, null, 7]), [good]);
  assert.deepEqual(foundParticles('particles'), []);
  assert.deepEqual(foundParticles(undefined), []);
});

test('a 250 nm particle on a 100 µm stage 600 px wide still rings 10 px', () => {
  // 6 px per µm: its own radius would be 1.5 px, under the tip's 12 px dot.
  assert.equal(MIN_RING_PX, 10);
  assert.equal(ringPx(250e-9, 600 / 100e-6), 10);
  assert.ok(Math.abs(ringPx(2e-6, 600 / 10e-6) - 120) < 1e-9, 'a big one at its own size');
});

test('the preview\'s arrow head points along the push, at its end', () => {
  const h = arrowHead([0, 0], [100, 0], 10, 5);
  assert.deepEqual(h, [[100, 0], [90, 5], [90, -5]]);
  const up = arrowHead([0, 100], [0, 0], 10, 5);
  assert.deepEqual(up[0], [0, 0]);
  assert.deepEqual([up[1][1], up[2][1]], [10, 10], 'behind the tip, upward on screen');
  assert.equal(arrowHead([1, 1], [1, 1]), null);
});
