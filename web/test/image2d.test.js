// node --test: the 2D image's axes and readout (src/image2d.js), DOM-free.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { niceStep, stageTicks, readoutText } from '../src/image2d.js';

test('tick steps are 1, 2 or 5 times a power of ten', () => {
  assert.equal(niceStep(10, 5), 2);
  assert.equal(niceStep(16, 5), 2);
  assert.equal(niceStep(40, 5), 10);
  assert.equal(niceStep(0.3, 5), 0.05);
  assert.equal(niceStep(1000, 4), 200);
});

test('a scan from 25 to 75 µm is labelled in stage µm, 30 to 70', () => {
  const t = stageTicks(25e-6, 50e-6);
  assert.deepEqual(t.map((k) => k.label), ['30', '40', '50', '60', '70']);
  assert.ok(Math.abs(t[2].m - 50e-6) < 1e-18, 'each tick at its stage coordinate');
});

test('the whole stage: ticks at 0 and 100 µm, both ends', () => {
  assert.deepEqual(stageTicks(0, 100e-6).map((k) => k.label), ['0', '20', '40', '60', '80', '100']);
});

test('a 1 µm scan at 40 µm: stage µm with the step\'s decimals', () => {
  assert.deepEqual(stageTicks(39.5e-6, 1e-6).map((k) => k.label), ['39.6', '39.8', '40.0', '40.2', '40.4']);
  assert.deepEqual(stageTicks(40e-6, 0.1e-6).map((k) => k.label), ['40.00', '40.02', '40.04', '40.06', '40.08', '40.10']);
});

test('the cursor readout is in the stage frame, µm to the nm', () => {
  assert.equal(readoutText(50e-6, 32.5e-6, 12.345e-9), 'stage x 50.000 µm, y 32.500 µm, height 12.35 nm');
  assert.equal(readoutText(0.5e-6, 0, NaN), 'stage x 0.500 µm, y 0.000 µm, height –');
});
