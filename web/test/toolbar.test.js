// node --test: the height exaggeration of the 3D toolbar (src/toolbar.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { clampExaggeration, exaggerationLabel, autoExaggerationFor } from '../src/toolbar.js';

test('"Auto": heights 15 % of the scan\'s shorter side; the slider 1-1000×', () => {
  // A 10 µm × 8 µm scan 40 nm deep: 0.15 × 8 µm / 40 nm = 30×.
  assert.ok(Math.abs(autoExaggerationFor({ x_real: 10e-6, y_real: 8e-6, min: -10e-9, max: 30e-9 }) - 30) < 1e-9);
  assert.equal(autoExaggerationFor({ x_real: 1e-6, y_real: 1e-6, min: 0, max: 0 }), null, 'flat');
  assert.equal(autoExaggerationFor({ x_real: 1e-6, y_real: 1e-6, min: Infinity, max: -Infinity }), null, 'no lines yet');
  assert.equal(autoExaggerationFor(null), null);
  // The tallest feature is kept within 8 pixel widths, so that a lone small particle is no
  // pillar: a 14 nm particle in a 50 µm, 256 px scan, 8 × 195 nm / 14 nm = 112× (15 % of the
  // side would be 535×).
  const gold = autoExaggerationFor({ x_real: 50e-6, y_real: 50e-6, xres: 256, yres: 256, min: 0, max: 14e-9 });
  assert.ok(Math.abs(gold - (8 * 50e-6) / 256 / 14e-9) < 1e-6, `${gold}`);
  assert.equal(clampExaggeration(0.2), 1);
  assert.equal(clampExaggeration(30), 30);
  assert.equal(clampExaggeration(5000), 1000);
  assert.deepEqual([1, 9.96, 10, 375.4].map(exaggerationLabel), ['1.0', '10.0', '10', '375']);
});
