// node --test: the scan's surface in the 3D view (src/surface3d.js) over the Session's scan
// state, filled as the server's lines arrive (three.js builds geometry without a DOM; nothing
// is drawn).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { ScanSurface, surfaceGrid, MAX_SIDE_SOFTWARE } from '../src/surface3d.js';
import { Session } from '../src/session.js';
import { encodeScanLine } from '../src/wire.js';

// A 4 × 4 scan of a 4 µm square at (10, 20) µm: every pixel a vertex (step 1).
function scan4(s = new Session()) {
  s.startScan({ scan: 7, xres: 4, yres: 4, x_offset: 10e-6, y_offset: 20e-6, x_real: 4e-6, y_real: 4e-6 });
  return s;
}
const line = (s, l, hs) => s.apply(encodeScanLine({ scan: 7, line: l, xres: 4, yres: 4, y: 0 }, hs));
const near = (a, b) => Math.abs(a - b) <= 1e-6 * Math.abs(b);
const rgbAt = (surface, row, a) => [...surface.mesh.geometry.getAttribute('color').array.slice(3 * (row * 4 + a), 3 * (row * 4 + a) + 3)];
const zAt = (surface, row, a) => surface.mesh.geometry.getAttribute('position').array[3 * (row * 4 + a) + 2];

// docs/server.md ("The Nano Visulator (`web/`)"): "a 512² scan is drawn in 3D from every 4th pixel
// (the 2D image keeps them all)": at most 160 vertices a side, so ceil(512/160) = 4, 128 × 128
// vertices.
test('a 512² scan is drawn in 3D from every 4th pixel', () => {
  assert.deepEqual(surfaceGrid(512, 512), { step: 4, nx: 128, ny: 128 });
  // Scans up to 160 pixels a side keep every pixel; 161 already takes every 2nd.
  assert.deepEqual(surfaceGrid(160, 160), { step: 1, nx: 160, ny: 160 });
  assert.deepEqual(surfaceGrid(161, 32), { step: 2, nx: 81, ny: 16 });
});

test('on a software renderer a 512² scan is drawn from every 7th pixel', () => {
  assert.equal(MAX_SIDE_SOFTWARE, 80);
  assert.deepEqual(surfaceGrid(512, 512, MAX_SIDE_SOFTWARE), { step: 7, nx: 74, ny: 74 });
  const s = new ScanSurface(new THREE.Group(), { maxSide: MAX_SIDE_SOFTWARE });
  s.start({ id: 1, xres: 512, yres: 512, x_offset: 0, y_offset: 0, x_real: 16e-6, y_real: 16e-6, heights: new Float32Array(512 * 512), received: new Uint8Array(512), lines: 0, min: 0, max: 0 });
  assert.equal(s.mesh.geometry.getAttribute('position').count, 74 * 74);
});

test('a new scan is an empty surface with an outline; the next replaces it', () => {
  const parent = new THREE.Group();
  const surface = new ScanSurface(parent);
  assert.equal(surface.sideUm(), null);
  assert.equal(surface.regionUm(), null);
  const s = scan4();
  surface.start(s.state.scan);
  assert.equal(parent.children.length, 2, 'the surface and its outline');
  assert.deepEqual(surface.mesh.geometry.drawRange, { start: 0, count: 0 }, 'nothing drawn before a line');
  const r = surface.regionUm();
  assert.ok(Math.abs(r.x0 - 10) < 1e-9 && Math.abs(r.y0 - 20) < 1e-9 && Math.abs(r.w - 4) < 1e-9 && Math.abs(r.h - 4) < 1e-9, JSON.stringify(r));
  assert.ok(Math.abs(surface.sideUm() - 4) < 1e-9);
  assert.equal(surface.shows(s.state.scan), true);
  scan4(s);
  s.state.scan.id = 8;
  assert.equal(surface.shows(s.state.scan), false);
  surface.start(s.state.scan);
  assert.equal(parent.children.length, 2, 'the old surface removed');
});

test('lines land on their rows in µm; drawn once contiguous from line 0', () => {
  const surface = new ScanSurface(new THREE.Group());
  const s = scan4();
  surface.start(s.state.scan);
  line(s, 0, [1e-9, 2e-9, NaN, 4e-9]);
  assert.equal(surface.line(s.state.scan, 0), true);
  // Line 0 is the lowest y: PlaneGeometry's last row. A missing height (NaN) sits at 0.
  assert.deepEqual([0, 1, 2, 3].map((a) => +zAt(surface, 3, a).toFixed(6)), [0.001, 0.002, 0, 0.004]);
  assert.deepEqual(surface.mesh.geometry.drawRange, { start: 54, count: 0 }, 'one row: no quads yet');
  line(s, 2, [0, 0, 0, 0]);
  surface.line(s.state.scan, 2);
  assert.equal(surface.mesh.geometry.drawRange.count, 0, 'line 1 missing: line 2 not drawn yet');
  line(s, 1, [0, 0, 0, 0]);
  surface.line(s.state.scan, 1);
  // 3 × 3 quads of 6 indices: rows 0-2 in is 2 quad rows, the last 36 of 54.
  assert.deepEqual(surface.mesh.geometry.drawRange, { start: 18, count: 36 });
  const other = scan4(new Session()).state.scan;
  other.id = 9;
  assert.equal(surface.line(other, 3), false, 'a line of another scan');
});

test('after a render a line uploads its row alone, before it all rows', () => {
  const surface = new ScanSurface(new THREE.Group());
  const s = scan4();
  surface.start(s.state.scan);
  const pos = surface.mesh.geometry.getAttribute('position');
  line(s, 0, [1e-9, 1e-9, 1e-9, 1e-9]);
  surface.line(s.state.scan, 0);
  assert.deepEqual(pos.updateRanges, [], 'a full upload pending is not narrowed');
  surface.uploaded();
  line(s, 1, [1e-9, 1e-9, 1e-9, 1e-9]);
  surface.line(s.state.scan, 1);
  // Line 1 is row 2 of 4: 4 vertices of 3 floats from float 24.
  assert.deepEqual(pos.updateRanges, [{ start: 24, count: 12 }]);
});

test('colour scale: 1 % margins, rescaled 2 % of the span past its ends', () => {
  const surface = new ScanSurface(new THREE.Group());
  const s = scan4();
  surface.start(s.state.scan);
  line(s, 0, [0, 100e-9, 50e-9, 50e-9]);
  surface.line(s.state.scan, 0);
  const r0 = surface.colourScale();
  assert.ok(near(r0.lo, -1e-9) && near(r0.hi, 101e-9), JSON.stringify(r0));
  line(s, 1, [0, 101.5e-9, 0, 0]);
  surface.line(s.state.scan, 1);
  assert.equal(surface.colourScale(), r0, '101.5 nm, within 101 + 2 % of 101.5 nm: the same scale');
  line(s, 2, [0, 105e-9, 0, 0]);
  surface.line(s.state.scan, 2);
  assert.ok(near(surface.colourScale().hi, 106.05e-9), '105 nm, beyond 101 + 2 % of 105 nm: rescaled');
  // The lowest and highest pixels take viridis's ends: dark violet (blue over red over green),
  // yellow (red over green over blue).
  const [r, g, b] = rgbAt(surface, 3, 0);
  assert.ok(b > r && r > g, `line 0's 0 nm: ${[r, g, b]}`);
  const [r2, g2, b2] = rgbAt(surface, 1, 1);
  assert.ok(r2 > g2 && g2 > b2, `line 2's 105 nm: ${[r2, g2, b2]}`);
});

test('coloured by the levelled heights when they fit the scan, else raw', () => {
  const surface = new ScanSurface(new THREE.Group());
  const s = scan4();
  assert.equal(surface.setColourSource({ values: new Float32Array(16), lo: -1e-9, hi: 1e-9 }), false, 'no scan yet');
  surface.start(s.state.scan);
  line(s, 0, [0, 10e-9, 0, 0]);
  surface.line(s.state.scan, 0);
  assert.equal(surface.setColourSource({ values: new Float32Array(16), lo: -2e-9, hi: 3e-9 }), true);
  assert.deepEqual(surface.colourScale(), { lo: -2e-9, hi: 3e-9 });
  assert.equal(surface.setColourSource({ values: new Float32Array(15), lo: -2e-9, hi: 3e-9 }), false, '15 values for 16 pixels');
  assert.ok(near(surface.colourScale().hi, 10.1e-9), 'the raw scale');
});

test('a whole scan at once; the height under a point, 0 off the scan', () => {
  const surface = new ScanSurface(new THREE.Group());
  const s = scan4();
  const heights = Float32Array.from({ length: 16 }, (_, i) => i * 1e-9);
  s.fillScan(7, heights);
  surface.fill(s.state.scan);
  assert.deepEqual(surface.mesh.geometry.drawRange, { start: 0, count: 54 }, 'all 3 × 3 quads');
  // (12.5, 21.5) µm: pixel 2 of line 1, 6 nm.
  assert.ok(Math.abs(surface.heightUnder(12.5, 21.5) - 0.006) < 1e-9);
  assert.equal(surface.heightUnder(9.9, 21.5), 0, 'left of the scan');
  assert.equal(surface.heightUnder(12.5, 24), 0, 'its top edge is outside');
  // The substrate goes below the lowest height (0 here) by 0.2 % of the scan's width.
  assert.ok(Math.abs(surface.floorUm(s.state.scan.min) + 0.008) < 1e-12);
  assert.ok(Math.abs(surface.floorUm(-5e-9) + 0.013) < 1e-12, 'and below a negative one');
  const live = scan4(new Session());
  surface.start(live.state.scan);
  line(live, 0, [5e-9, 5e-9, 5e-9, 5e-9]);
  assert.ok(Math.abs(surface.heightUnder(12.5, 20.5) - 0.005) < 1e-9);
  assert.equal(surface.heightUnder(12.5, 21.5), 0, 'line 1 not received');
});

test('picking recomputes the surface\'s bounds after new lines', () => {
  const surface = new ScanSurface(new THREE.Group());
  assert.equal(surface.pickable(), null);
  const s = scan4();
  surface.start(s.state.scan);
  line(s, 0, [1e-6, 1e-6, 1e-6, 1e-6]);
  surface.line(s.state.scan, 0);
  assert.equal(surface.boundsDirty, true);
  const mesh = surface.pickable();
  assert.equal(mesh, surface.mesh);
  assert.equal(surface.boundsDirty, false);
  assert.equal(mesh.geometry.boundingBox.max.z, 1, 'the 1 µm line');
});
