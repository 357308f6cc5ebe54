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
