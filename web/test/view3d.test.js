// node --test: the 3D view's camera framing (src/view3d.js; three.js loads without a DOM, the
// view itself needs a browser: e2e/visulator.e2e.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { framingPose } from '../src/view3d.js';

/** The box's corners on screen (normalised device coordinates) seen from `framingPose`'s pose. */
function cornersOnScreen(aspect, x0, y0, w, h) {
  const pose = framingPose(40, aspect, x0, y0, w, h);
  const cam = new THREE.PerspectiveCamera(40, aspect, pose.near, pose.far);
  cam.up.set(0, 0, 1);
  cam.position.set(...pose.position);
  cam.lookAt(...pose.target);
  cam.updateMatrixWorld();
  cam.updateProjectionMatrix();
  return [[x0, y0], [x0 + w, y0], [x0, y0 + h], [x0 + w, y0 + h]].map(([x, y]) => new THREE.Vector3(x, y, 0).project(cam));
}

test('the whole box is in view in wide, square, and tall narrow views', () => {
  for (const aspect of [2.5, 1, 0.4]) {
    for (const [w, h] of [[100, 60], [100, 100], [60, 100]]) {
      const ps = cornersOnScreen(aspect, 20, 30, w, h);
      const reach = Math.max(...ps.map((p) => Math.max(Math.abs(p.x), Math.abs(p.y))));
      assert.ok(reach < 1, `aspect ${aspect}, ${w} × ${h} µm: a corner at ${reach.toFixed(3)} of the half-view`);
    }
  }
});

test('the camera looks at the box\'s centre from the south, 42° up', () => {
  const pose = framingPose(40, 1.5, 0, 0, 100, 100);
  assert.deepEqual(pose.target, [50, 50, 0]);
  const [x, y, z] = pose.position;
  assert.equal(x, 50);
  assert.ok(y < 50, 'south of the centre');
  const up = (Math.atan2(z, 50 - y) * 180) / Math.PI;
  assert.ok(Math.abs(up - 41.82) < 0.01, `${up.toFixed(2)}°`);
  assert.ok(pose.near < 1 && pose.far > 1000, `near ${pose.near}, far ${pose.far} µm`);
});

test('the distance: the box\'s corners 8 % inside the narrower field of view', () => {
  // A 100 µm square's corners are 70.7 µm from its centre; 1.08 × 70.7 / sin(half the field).
  const dist = (aspect) => {
    const { target, position } = framingPose(40, aspect, 0, 0, 100, 100);
    return Math.hypot(...position.map((v, i) => v - target[i]));
  };
  assert.ok(Math.abs(dist(1) - 223.28) < 0.01, `square: the 20° half-field, ${dist(1)}`);
  assert.ok(Math.abs(dist(2.5) - 223.28) < 0.01, 'wide: the same vertical field');
  // Tall and narrow (0.4): the horizontal half-field, atan(tan 20° × 0.4) = 8.28°.
  assert.ok(Math.abs(dist(0.4) - 530.08) < 0.01, `tall: ${dist(0.4)}`);
});
