// node --test: the push's marks in the 3D view (src/marks3d.js): the target, the form's preview
// arrow and the commanded path (three.js builds geometry without a DOM; nothing is drawn).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { PushMarks } from '../src/marks3d.js';

const marks = () => new PushMarks(new THREE.Group(), new THREE.Group());
const round = (v) => v.toArray().map((x) => +x.toFixed(6));

test('the target at a picked point, sized as the markers; null hides it', () => {
  const m = marks();
  assert.equal(m.target.visible, false);
  m.setTarget(12, 34, 0.5);
  assert.equal(m.target.visible, true);
  assert.deepEqual(round(m.target.position), [12, 34, 0.02]);
  assert.equal(m.target.scale.x, 0.5);
  m.setTarget(null);
  assert.equal(m.target.visible, false);
});

test('the preview: an arrow of the push, lifted as the heights are', () => {
  const m = marks();
  // 4 µm along 90° from a particle 10 nm up, the heights exaggerated 20×: 0.2 µm up.
  m.setPreview({ x: 5, y: 6, z: 0.01 }, 90, 4, 0.5, 20);
  assert.equal(m.preview.visible, true);
  assert.deepEqual(round(m.preview.position), [5, 6, 0.2]);
  const dir = new THREE.Vector3(0, 1, 0).applyQuaternion(m.preview.quaternion);
  assert.deepEqual(round(dir), [0, 1, 0], 'along +y');
  // The arrow's length is its line (scale.y) and its head: a head of min(0.3 × 4, 2 × 0.5) = 1 µm.
  assert.ok(Math.abs(m.preview.line.scale.y + m.preview.cone.scale.y - 4) < 1e-9);
  assert.ok(Math.abs(m.preview.cone.scale.y - 1) < 1e-9);
  m.setExaggeration(1);
  assert.deepEqual(round(m.preview.position), [5, 6, 0.05], 'never below 0.05 µm');
  m.setPreview({ x: 5, y: 6 }, 90, 0, 0.5, 1);
  assert.equal(m.preview.visible, false, 'no length, no arrow');
});

test('the push path: its points in µm, a line and an arrowhead at the end', () => {
  const m = marks();
  m.setPushPath([[10e-6, 20e-6], [10e-6, 22e-6], [13e-6, 22e-6]], 0.5);
  assert.equal(m.pushPath.visible, true);
  assert.deepEqual(m.pathPoints.map((p) => p.map((v) => +v.toFixed(9))), [[10, 20], [10, 22], [13, 22]]);
  assert.equal(m.pushPath.children.length, 2, 'the line and the arrowhead');
  const line = m.pushPath.children[0].geometry.getAttribute('position');
  assert.equal(line.count, 3);
  assert.ok(Math.abs(line.getZ(0) - 0.1) < 1e-6, '0.2 × the marker above the substrate');
  m.setPushPath([[10e-6, 20e-6]], 0.5);
  assert.equal(m.pushPath.visible, false, 'one point is no path');
  assert.equal(m.pathPoints, null);
  assert.equal(m.pushPath.children.length, 0);
});
