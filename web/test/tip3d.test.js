// node --test: the tip in the 3D view (src/tip3d.js): the ball, its drop line, shadow, trail and
// the estimate, from telemetry (three.js builds geometry without a DOM; nothing is drawn).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { TipMarker, TRAIL_N, TIP_MIN_PX } from '../src/tip3d.js';

const marker = () => new TipMarker(new THREE.Group(), new THREE.Group());
const flat = { markerUm: 0.5, exaggeration: 1, surfaceUnder: () => 0 };
const tipAt = (x, y, z, estimate = null) => ({ stage: [x, y, z], estimate });

test('the ball sits on the apex, heights exaggerated; a drop line below', () => {
  const m = marker();
  // 20 nm up over a 5 nm surface, exaggerated 100×: 2 µm and 0.5 µm.
  assert.equal(m.set(tipAt(10e-6, 20e-6, 20e-9), { markerUm: 0.5, exaggeration: 100, surfaceUnder: () => 0.005 }), true);
  assert.equal(m.ball.visible, true);
  assert.equal(m.r, 0.3, '0.6 of the marker size');
  const p = m.ball.position;
  assert.ok(Math.abs(p.x - 10) < 1e-9 && Math.abs(p.y - 20) < 1e-9 && Math.abs(p.z - 2.3) < 1e-9, `${p.toArray()}`);
  const d = m.dropGeom.getAttribute('position');
  assert.ok(Math.abs(d.getZ(0) - 2) < 1e-6 && Math.abs(d.getZ(1) - 0.5) < 1e-6, `${d.getZ(0)} ${d.getZ(1)}`);
  assert.ok(Math.abs(m.shadow.position.z - 0.5) < 1e-9);
  assert.equal(m.ball.material.depthTest, false, 'drawn through the scan and the particles');
  assert.equal(m.set(null, flat), true);
  assert.equal(m.ball.visible, false);
  assert.equal(m.drop.visible, false);
});

test('an idle tip (same position and estimate) costs no frame', () => {
  const m = marker();
  assert.equal(m.set(tipAt(1e-6, 1e-6, 0), flat), true);
  assert.equal(m.set(tipAt(1e-6, 1e-6, 0), flat), false);
  assert.equal(m.trailLen, 1);
  assert.equal(m.set(tipAt(1e-6, 1e-6, 0, [2e-6, 1e-6]), flat), true, 'an estimate came');
  assert.equal(m.set(tipAt(1e-6, 1e-6, 0, [2e-6, 1e-6]), { ...flat, exaggeration: 5, addTrail: false }), true, 'redrawn for a new exaggeration');
  assert.equal(m.trailLen, 2, 'without a trail point');
});

test('the trail keeps the newest positions, oldest first', () => {
  const m = marker();
  for (let i = 0; i < TRAIL_N + 5; i++) m.set(tipAt(i * 1e-6, 0, 0), flat);
  assert.equal(m.trailLen, TRAIL_N, `${TRAIL_N} positions`);
  assert.deepEqual(m.trail.geometry.drawRange, { start: 0, count: 900 });
  assert.equal(m.trailPos[0], 5, 'positions 0-4 dropped');
  assert.equal(m.trailPos[3 * (TRAIL_N - 1)], 904);
  m.clearTrail();
  assert.equal(m.trail.geometry.drawRange.count, 0);
});

test('the pushed particle\'s estimate: a ring, hidden without one', () => {
  const m = marker();
  m.set(tipAt(1e-6, 1e-6, 0, [3e-6, 4e-6]), flat);
  assert.equal(m.estimate.visible, true);
  assert.deepEqual(m.estimate.position.toArray().map((v) => +v.toFixed(9)), [3, 4, 0.01]);
  assert.equal(m.estimate.scale.x, 0.6, 'twice the ball');
  m.set(tipAt(2e-6, 1e-6, 0), flat);
  assert.equal(m.estimate.visible, false);
});

test('the ball keeps a minimum size on screen however far the camera is', () => {
  const m = marker();
  m.set(tipAt(0, 0, 0), flat);
  const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 20000);
  // 1000 µm away, 700 px tall: 2·1000·tan 20° / 700 = 1.04 µm a pixel, 7.28 µm for 7 px.
  camera.position.set(0, 0, 1000 + m.ball.position.z);
  m.scaleToScreen(camera, 700);
  const perPx = (2 * 1000 * Math.tan((20 * Math.PI) / 180)) / 700;
  assert.equal(TIP_MIN_PX, 7);
  assert.ok(Math.abs(m.ball.scale.x - 7 * perPx) < 1e-9, `7 px: ${m.ball.scale.x} µm`);
  assert.ok(Math.abs(m.shadow.scale.x - 1.1 * 7 * perPx) < 1e-9);
  // Close by, its own size (0.3 µm) is more than 7 px.
  camera.position.set(0, 0, 1 + m.ball.position.z);
  m.scaleToScreen(camera, 700);
  assert.equal(m.ball.scale.x, 0.3);
});
