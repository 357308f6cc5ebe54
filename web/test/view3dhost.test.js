// node --test: the 3D view's host (src/view3dhost.js): nothing loaded until the view is first
// shown, then the view built from what was kept, and every call handed on.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { View3DHost } from '../src/view3dhost.js';

/** A View3D that writes down what it is told. */
function fakeModule(calls) {
  class View3D {
    constructor(container, handlers, scheduler, opts) {
      calls.push(['new', opts]);
      return new Proxy(this, {
        get: (t, k) => (k in t ? t[k] : (...a) => { calls.push([k, ...a]); }),
      });
    }

    colourScale() {
      return { lo: -1, hi: 1 };
    }
  }
  return { View3D };
}

const scan = { id: 3, min: -2e-9, max: 5e-9 };

test('hidden, nothing is loaded; what it is to show is kept', async () => {
  let loads = 0;
  const calls = [];
  const h = new View3DHost({}, {}, {}, { software: true, load: async () => { loads++; return fakeModule(calls); } });
  h.setStage(50);
  h.setParticles([{ id: 1 }], 1);
  h.startScan(scan);
  h.setTip({ stage: [1, 2, 3] });
  h.setPushPath([[0, 0], [1, 0]]);
  h.setPreview({ x: 1, y: 2, z: 0 }, 90, 5);
  h.setExaggeration(12);
  h.frameScan();
  await h.setShown(false);
  assert.equal(loads, 0, 'no three.js for a hidden view');
  assert.equal(h.loaded, false);
  assert.deepEqual(h.colourScale(), { lo: -2e-9, hi: 5e-9 }, 'the legend from the scan meanwhile');
  assert.equal(h.frames, 0);
  await h.setShown(true);
  assert.equal(loads, 1);
  const names = calls.map((c) => c[0]);
  assert.deepEqual(names, ['new', 'setStage', 'setExaggeration', 'setParticles', 'fillScan', 'setColourSource', 'setTip', 'setPushPath', 'setPreview', 'frameScan', 'setShown']);
  assert.deepEqual(Object.keys(calls[0][1]), ['software', 'slot']);
  assert.equal(calls[0][1].software, true);
  assert.deepEqual(calls.find((c) => c[0] === 'setStage'), ['setStage', 50]);
  assert.deepEqual(calls.find((c) => c[0] === 'setPreview'), ['setPreview', { x: 1, y: 2, z: 0 }, 90, 5]);
  assert.deepEqual(calls.find((c) => c[0] === 'fillScan'), ['fillScan', scan]);
});

test('once built, each call goes to the view; it loads once', async () => {
  let loads = 0;
  const calls = [];
  const h = new View3DHost({}, {}, {}, { software: false, load: async () => { loads++; return fakeModule(calls); } });
  await Promise.all([h.setShown(true), h.setShown(true)]);
  calls.length = 0;
  h.setTarget(3, 4);
  h.scanLine(scan, 7);
  await h.setShown(false);
  await h.setShown(true);
  assert.equal(loads, 1);
  assert.deepEqual(calls, [['setTarget', 3, 4], ['scanLine', scan, 7], ['setShown', false], ['setShown', true]]);
  assert.deepEqual(h.colourScale(), { lo: -1, hi: 1 }, 'the view\'s own scale');
});

test('a load that fails is tried again the next time the view is shown', async () => {
  let loads = 0;
  const calls = [];
  const h = new View3DHost({}, {}, {}, { software: true, load: async () => {
    loads++;
    if (loads === 1) throw new Error('Failed to fetch dynamically imported module');
    return fakeModule(calls);
  } });
  await assert.rejects(h.setShown(true), /Failed to fetch/);
  assert.equal(h.loaded, false);
  await h.setShown(true);
  assert.equal(loads, 2);
  assert.equal(h.loaded, true);
});
