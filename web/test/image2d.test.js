// node --test: the 2D image's tick steps (src/image2d.js), DOM-free.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { niceStep } from '../src/image2d.js';

test('tick steps are 1, 2 or 5 times a power of ten', () => {
  assert.equal(niceStep(10, 5), 2);
  assert.equal(niceStep(16, 5), 2);
  assert.equal(niceStep(40, 5), 10);
  assert.equal(niceStep(0.3, 5), 0.05);
  assert.equal(niceStep(1000, 4), 200);
});
