// node --test: the particles in the 3D view (src/particles3d.js). three.js builds the spheres
// without a DOM; the labels' elements are stand-ins with what CSS2DObject and the view touch.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { ParticleSpheres, shownRadiusUm, particleTitle } from '../src/particles3d.js';

function element() {
  const classes = new Set();
  return {
    style: {},
    removed: false,
    setAttribute() {},
    remove() { this.removed = true; },
    classList: { toggle: (c, on) => (on ? classes.add(c) : classes.delete(c)), contains: (c) => classes.has(c) },
  };
}
globalThis.document = { createElement: element };

const gold = { id: 1, radius: 7e-9, x: 10e-6, y: 20e-6, material: 'gold' };
const big = { id: 2, radius: 1e-6, x: 30e-6, y: 40e-6, material: '' };

test('tiny particles are drawn at a minimum size, larger ones as they are', () => {
  // A 7 nm particle on a 100 µm stage: 0.4 µm; a 1 µm one: 1 µm.
  assert.equal(shownRadiusUm(7e-9, 100), 0.4, 'stage/250');
  assert.equal(shownRadiusUm(1e-6, 100), 1);
});

test('a particle\'s tooltip: id, material when known, radius', () => {
  assert.equal(particleTitle(gold), 'particle 1 (gold), radius 7.0 nm');
  assert.equal(particleTitle(big), 'particle 2, radius 1.00 µm');
});

test('spheres labelled with ids, on the substrate, the selected highlighted', () => {
  const parent = new THREE.Group();
  const ps = new ParticleSpheres(parent);
  ps.set([gold, big], 2, 100, false);
  assert.equal(ps.meshes.size, 2);
  const [m1, m2] = [ps.meshes.get(1), ps.meshes.get(2)];
  assert.equal(m1.scale.x, 0.4);
  assert.deepEqual(ps.centre(1).toArray().map((v) => +v.toFixed(9)), [10, 20, 0.007], 'its centre a radius up');
  assert.equal(m1.children[0].element.textContent, '#1');
  assert.equal(m1.children[0].element.title, 'particle 1 (gold), radius 7.0 nm');
  assert.equal(m2.children[0].element.classList.contains('selected'), true);
  assert.equal(m2.material.color.getHex(), 0xffe08a);
  assert.equal(m2.material.opacity, 0.6);
  assert.equal(m1.material.color.getHex(), 0xe6c35c);
  assert.equal(m1.material.opacity, 0.4);
  // Over a scan they are half as opaque, so the surface shows through; a move follows the store.
  ps.update([{ ...gold, x: 12e-6 }, big], 1, true);
  assert.equal(m1.material.opacity, 0.3);
  assert.equal(m2.material.opacity, 0.2);
  assert.equal(m1.children[0].element.classList.contains('selected'), true);
  assert.equal(m2.children[0].element.classList.contains('selected'), false);
  assert.ok(Math.abs(ps.centre(1).x - 12) < 1e-9);
  assert.equal(ps.centre(3), null);
});

test('a new set of particles replaces the spheres and removes the old labels', () => {
  const ps = new ParticleSpheres(new THREE.Group());
  ps.set([gold, big], null, 100, false);
  const old = ps.meshes.get(2).children[0].element;
  ps.set([gold], null, 100, false);
  assert.equal(ps.group.children.length, 1);
  assert.equal(old.removed, true);
  assert.equal(ps.centre(2), null);
});
