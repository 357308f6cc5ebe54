import { test } from 'node:test';
import assert from 'node:assert/strict';
import { viridis, viridisTable } from '../src/colormap.js';

test('viridis: dark purple to yellow, brighter all the way, clamped', () => {
  assert.deepEqual(viridis(0).map((c) => Math.round(c * 255)), [68, 1, 84]);
  assert.deepEqual(viridis(1).map((c) => Math.round(c * 255)), [253, 231, 37]);
  assert.deepEqual(viridis(-3), viridis(0));
  assert.deepEqual(viridis(NaN), viridis(0));
  assert.deepEqual(viridis(7), viridis(1));
  const t = viridisTable(64);
  assert.equal(t.length, 192);
  // Perceptual: the luma rises monotonically along the map.
  let prev = -1;
  for (let i = 0; i < 64; i++) {
    const y = 0.2126 * t[3 * i] + 0.7152 * t[3 * i + 1] + 0.0722 * t[3 * i + 2];
    assert.ok(y > prev, `luma at ${i}`);
    prev = y;
  }
});
