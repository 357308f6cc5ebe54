// node --test: the page's formatters (src/format.js), the one length formatter's two styles
// pinned as the page shows them.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { lengthUnit, formatLength, formatPoint, formatStagePoint, formatTip, formatBytes, formatTime } from '../src/format.js';

test('lengths take nm below 2 µm and µm above', () => {
  assert.deepEqual(lengthUnit(14e-9), { name: 'nm', scale: 1e9 });
  assert.deepEqual(lengthUnit(16e-6), { name: 'µm', scale: 1e6 });
  assert.equal(formatLength(250e-9, { digits: 3 }), '250 nm');
  assert.equal(formatLength(12.5e-6, { digits: 3 }), '12.5 µm');
});

// The default style: the colour legend, particle radii ("#1 latex (r 500 nm)") and scan sizes
// ("32×32 px, 10.0 µm square") of the page, and the 3D view's particle tooltips.
test('formatLength by default: fixed decimals, nm below 1 µm, µm above', () => {
  assert.equal(formatLength(500e-9), '500 nm');
  assert.equal(formatLength(7e-9), '7.0 nm', 'one decimal below 10 nm');
  assert.equal(formatLength(14e-9), '14 nm');
  assert.equal(formatLength(-3.25e-9), '-3.3 nm');
  assert.equal(formatLength(0), '0.0 nm');
  assert.equal(formatLength(1e-6), '1.00 µm', '1 µm is µm already (the unit switch of lengthUnit is 2 µm)');
  assert.equal(formatLength(1.5e-6), '1.50 µm');
  assert.equal(formatLength(9.994e-6), '9.99 µm');
  assert.equal(formatLength(10e-6), '10.0 µm');
  assert.equal(formatLength(16e-6), '16.0 µm');
});

// With `digits`: significant digits, in the unit of `ref` (the 2D image's scale bar: 6 digits, the
// unit of the scan's larger side) or, without one, of the length itself.
test('formatLength with digits: significant digits in lengthUnit(ref)\'s unit', () => {
  assert.equal(formatLength(1.5e-6, { digits: 3 }), '1500 nm', 'below 2 µm: nm, where the default says 1.50 µm');
  assert.equal(formatLength(2e-6, { digits: 3 }), '2 µm');
  assert.equal(formatLength(123.456e-9, { digits: 3 }), '123 nm');
  assert.equal(formatLength(123.456e-9, { digits: 6 }), '123.456 nm');
  // The scale bar of a 10 µm scan: 2 µm; of a 16 µm scan with a 500 nm bar: in µm all the same.
  assert.equal(formatLength(2e-6, { digits: 6, ref: 10e-6 }), '2 µm');
  assert.equal(formatLength(500e-9, { digits: 6, ref: 16e-6 }), '0.5 µm');
  assert.equal(formatLength(0.2e-6, { digits: 6, ref: 1e-6 }), '200 nm');
  // Float noise does not show: 0.30000000000000004 µm → 0.3.
  assert.equal(formatLength(0.1e-6 + 0.2e-6, { digits: 6, ref: 5e-6 }), '0.3 µm');
});

test('points, the tip readout, sizes and times', () => {
  assert.equal(formatPoint([5e-5, 6e-5]), '(50.00, 60.00) µm');
  assert.equal(formatPoint([5e-8, -6e-8]), '(0.05, -0.06) µm', 'a stage point is µm near the origin too');
  assert.equal(formatStagePoint([40e-6, 31.5e-6]), '(40.000, 31.500) µm');
  const tip = { stage: [40e-6, 30.25e-6, 1.2e-6], volts: -0.2, phase: 'approach', force: 2.5e-9, estimate: null };
  assert.equal(formatTip(tip), 'tip (40.000, 30.250) µm · z 1200.0 nm · 2.50 nN · -0.200 V');
  assert.equal(formatTip({ ...tip, force: undefined, estimate: [41e-6, 30e-6] }), 'tip (40.000, 30.250) µm · z 1200.0 nm · 0.00 nN · -0.200 V');
  assert.deepEqual([formatBytes(512), formatBytes(2048), formatBytes(3.5 * 1024 * 1024), formatBytes(undefined)], ['512 B', '2.0 KiB', '3.5 MiB', '']);
  assert.equal(formatTime(null), '');
  assert.equal(formatTime('not a date'), 'not a date');
  // Seconds and milliseconds since the epoch are the same time.
  assert.equal(formatTime(1.7e9), formatTime(1.7e12));
  assert.equal(formatTime(1.7e9), new Date(1.7e12).toLocaleString());
});
