// node --test: the legend's progress line and the image's title (src/scans.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { progressText, scanTitle } from '../src/scans.js';

test('progress of the live scan, complete, stale', () => {
  assert.equal(progressText({ id: 3, done: false, lines: 12, yres: 32 }, false), 'scan 3: line 12/32');
  assert.equal(progressText({ id: 3, done: true, lines: 32, yres: 32 }, false), 'scan 3 complete');
  assert.equal(progressText({ id: 3, done: true, lines: 32, yres: 32 }, true), 'scan 3 complete · stale (a push ran since)');
});

test('the image\'s title: a record opened, else the live scan', () => {
  assert.equal(scanTitle(null, { id: 7 }), '· scan 7');
  assert.equal(scanTitle('scan-1-2.gsf', { id: -1 }), '· record scan-1-2.gsf');
});

test('a scan the server never finished (it restarted) says it was cut off', () => {
  // Not "line 44/512", as if it ran on.
  assert.equal(progressText({ id: 1, done: false, interrupted: true, previousRun: true, lines: 44, yres: 512 }, true), 'scan 1 interrupted at line 44/512 · from before the server restarted');
  assert.equal(progressText({ id: 1, done: true, previousRun: true, lines: 32, yres: 32 }, true), 'scan 1 complete · from before the server restarted');
});
