// node --test: a scan's heights levelled and along a profile (src/heightmap.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { level, profileAlong } from '../src/heightmap.js';

function scanOf(xres, yres, f, received = null) {
  const heights = new Float32Array(xres * yres);
  for (let j = 0; j < yres; j++) for (let i = 0; i < xres; i++) heights[j * xres + i] = f(i, j);
  return { xres, yres, heights, received: received ?? new Uint8Array(yres).fill(1) };
}

test('mean-plane levelling removes a tilted plane exactly', () => {
  const s = scanOf(16, 12, (i, j) => 1e-8 + 2e-9 * i - 3e-9 * j);
  const out = level(s, 'plane');
  // Least squares of z = a + b i + c j.
  for (const v of out) assert.ok(Math.abs(v) < 1e-14, `residual ${v}`);
  // A bump on the plane stays, the plane goes: the corners sit at the same level.
  // (A bump symmetric about the centre does not tilt the fitted plane.)
  const b = scanOf(16, 16, (i, j) => 5e-9 * i + ((i - 7.5) ** 2 + (j - 7.5) ** 2 < 4 ? 1e-7 : 0));
  const lb = level(b, 'plane');
  assert.ok(Math.abs(lb[0] - lb[15]) < 1e-12 && Math.abs(lb[0] - lb[15 * 16 + 15]) < 1e-12);
  assert.ok(lb[8 * 16 + 8] - lb[0] > 0.9e-7);
});

test('line-by-line levelling takes each line\'s mean; missing lines are NaN', () => {
  const rec = new Uint8Array([1, 1, 0, 1]);
  const s = scanOf(4, 4, (i, j) => j * 1e-9 + (i === 0 ? 4e-9 : 0), rec);
  const out = level(s, 'line');
  assert.ok(Math.abs(out[0] - 3e-9) < 1e-15 && Math.abs(out[1] + 1e-9) < 1e-15);
  assert.ok(Math.abs(out[3 * 4] - 3e-9) < 1e-15, 'each line on its own');
  assert.ok(Number.isNaN(out[2 * 4]), 'line 2 not received');
  const none = level(s, 'none');
  assert.equal(none[5], s.heights[5]);
});

test('a profile reads a row\'s pixels and interpolates along a diagonal', () => {
  const s = scanOf(5, 5, (i, j) => i + 10 * j);
  const row = profileAlong(s.heights, 5, 5, 0, 2, 4, 2);
  assert.deepEqual([...row.h], [20, 21, 22, 23, 24]);
  assert.equal(row.t[4], 1);
  const diag = profileAlong(s.heights, 5, 5, 0, 0, 4, 4);
  assert.equal(diag.h.length, 7);
  assert.ok(Math.abs(diag.h[3] - 22) < 1e-12, `${diag.h[3]}`);
});
