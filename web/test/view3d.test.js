// node --test: the 3D view's surface grid (three.js loads without a DOM; nothing is drawn).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { surfaceGrid } from '../src/view3d.js';

// docs/server.md ("The Nano Visulator (`web/`)"): "a 512² scan is drawn in 3D from every 4th pixel
// (the 2D image keeps them all)": at most 160 vertices a side, so ceil(512/160) = 4, 128 × 128
// vertices.
test('a 512² scan is drawn in 3D from every 4th pixel', () => {
  assert.deepEqual(surfaceGrid(512, 512), { step: 4, nx: 128, ny: 128 });
  // Scans up to 160 pixels a side keep every pixel; 161 already takes every 2nd.
  assert.deepEqual(surfaceGrid(160, 160), { step: 1, nx: 160, ny: 160 });
  assert.deepEqual(surfaceGrid(161, 32), { step: 2, nx: 81, ny: 16 });
});
