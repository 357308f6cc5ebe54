// node --test: the plots' data (src/charts.js): the CSV export and the windows of the trace the
// three plots show (uPlot itself is not run).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { traceCsv, chartData, csvFileName, CHART_PERIOD_MS } from '../src/charts.js';

const trace = (rows) => ({
  seconds: 10,
  t: rows.map((r) => r[0]),
  z: rows.map((r) => r[1]),
  volts: rows.map((r) => r[2]),
  force: rows.map((r) => r[3]),
});

test('traceCsv: one row per sample in SI units; a missing force is empty', () => {
  const csv = traceCsv(trace([[1.5, 2e-6, -0.2, 3e-9], [1.6, 1.9e-6, -0.25, undefined]]));
  assert.equal(csv, 't_s,z_m,volts,tip_force_n\n1.5,0.000002,-0.2,3e-9\n1.6,0.0000019,-0.25,\n');
  assert.equal(traceCsv(trace([])), 't_s,z_m,volts,tip_force_n\n');
});

test('chartData: seconds to the newest sample, nN with the set point, µm', () => {
  const tr = trace([[10, 2e-6, 0, 1e-9], [10.5, 1.5e-6, 0, 2e-9], [12, 1e-6, 0, 26e-9]]);
  const d = chartData(tr, -Infinity, 26e-9);
  assert.deepEqual([...d.force[0]], [-2, -1.5, 0]);
  assert.deepEqual([...d.force[1]].map((v) => +v.toFixed(9)), [1, 2, 26]);
  assert.deepEqual([...d.force[2]].map((v) => +v.toFixed(9)), [26, 26, 26], 'the set point, 26 nN, at every sample');
  assert.deepEqual([...d.z[0]], [-2, -1.5, 0]);
  assert.deepEqual([...d.z[1]].map((v) => +v.toFixed(9)), [2, 1.5, 1]);
  // No set point: NaN, which uPlot leaves out.
  assert.ok(chartData(tr).force[2].every(Number.isNaN));
  // An empty trace: empty columns.
  const e = chartData(trace([]));
  assert.deepEqual([e.force[0].length, e.z[1].length, e.fd[0].length], [0, 0, 0]);
});

test('chartData: force against height since the push began, by height', () => {
  // Samples before `since` (an earlier approach) are left out of the force-distance plot only.
  const tr = trace([[1, 5e-6, 0, 9e-9], [2, 1.003e-6, 0, 3e-9], [3, 1e-6, 0, 10e-9], [4, 1.001e-6, 0, 5e-9], [5, 1.002e-6, 0, 4e-9]]);
  const d = chartData(tr, 2, null);
  assert.equal(d.force[0].length, 5, 'the time plots keep the whole window');
  assert.deepEqual([...d.fd[0]].map((v) => +v.toFixed(6)), [0, 1, 2, 3], 'heights (nm) above the lowest, ascending');
  assert.deepEqual([...d.fd[1]].map((v) => +v.toFixed(6)), [10, 5, 4, 3], 'forces in the same order');
  assert.equal(d.fd[2].length, 4);
  assert.equal(chartData(tr, 99).fd[0].length, 0, 'nothing since then');
  assert.equal(chartData(tr).fd[0].length, 5, 'no push yet: the whole window');
});

test('the CSV file is named by its download time; plots redraw at most 5/s', () => {
  assert.equal(csvFileName(new Date(Date.UTC(2024, 4, 1, 12, 3, 4, 567))), 'nanopush-trace-2024-05-01T12-03-04-567Z.csv');
  assert.ok(1000 / CHART_PERIOD_MS <= 5, `${1000 / CHART_PERIOD_MS} redraws a second`);
});
