// node --test: the Assemble panel's presets (src/presets.js) against the instrument's generators.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { presetSites, presetSpec, PRESETS, MAX_SITES } from '../src/presets.js';

const near = (a, b) => a.length === b.length && a.every((p, k) => Math.hypot(p[0] - b[k][0], p[1] - b[k][1]) < 1e-9);

test('a line is centred on its point and turned by its angle', () => {
  // pattern.rs: line:n=3,spacing_um=4,angle_deg=90 at (50, 40) → (50, 36), (50, 40), (50, 44).
  const s = presetSites('line', { n: 3, spacing_um: 4, angle_deg: 90 }, [50, 40]);
  assert.ok(near(s, [[50, 36], [50, 40], [50, 44]]), JSON.stringify(s));
  assert.ok(near(presetSites('line', { n: 2, spacing_um: 4 }, [10, 10]), [[8, 10], [12, 10]]), 'no angle: along +x');
});

test('a grid goes row by row from its top, its spacing between neighbours', () => {
  const s = presetSites('grid', { rows: 2, cols: 3, spacing_um: 5 }, [50, 50]);
  assert.ok(near(s, [[45, 52.5], [50, 52.5], [55, 52.5], [45, 47.5], [50, 47.5], [55, 47.5]]), JSON.stringify(s));
});

test('a ring starts at angle 0 and goes anticlockwise, on its radius', () => {
  const s = presetSites('ring', { n: 4, radius_um: 6, angle_deg: 0 }, [40, 60]);
  assert.ok(near(s, [[46, 60], [40, 66], [34, 60], [40, 54]]), JSON.stringify(s));
  const turned = presetSites('ring', { n: 4, radius_um: 6, angle_deg: 90 }, [40, 60]);
  assert.ok(near(turned, [[40, 66], [34, 60], [40, 54], [46, 60]]));
});

test('a parameter out of range names itself, its value and the allowed range', () => {
  const msg = (kind, p) => {
    try {
      presetSites(kind, p, [50, 50]);
    } catch (e) {
      return e.message;
    }
    return 'no error';
  };
  assert.throws(() => presetSites('line', { n: 1, spacing_um: 4 }, [50, 50]), RangeError);
  assert.equal(msg('line', { n: 1, spacing_um: 4 }), 'line sites: 1 is out of range; allowed: a whole number in [2, 400]');
  assert.equal(msg('ring', { n: 2, radius_um: 4 }), 'ring sites: 2 is out of range; allowed: a whole number in [3, 400]');
  assert.equal(msg('line', { n: 2.5, spacing_um: 4 }), 'line sites: 2.5 is out of range; allowed: a whole number in [2, 400]');
  assert.equal(msg('line', { n: 3, spacing_um: 0 }), 'line spacing: 0 is out of range; allowed: (0, 1000] µm');
  assert.equal(msg('ring', { n: 3, radius_um: 1001 }), 'ring radius: 1001 is out of range; allowed: (0, 1000] µm');
  assert.equal(msg('ring', { n: 3, radius_um: 5, angle_deg: 400 }), 'ring angle: 400 is out of range; allowed: [-360, 360]°');
  assert.equal(msg('grid', { rows: 1, cols: 1, spacing_um: 4 }), 'grid rows × columns: 1 sites is out of range; allowed: [2, 400] sites');
  assert.equal(msg('grid', { rows: 21, cols: 20, spacing_um: 1 }), `grid rows × columns: 420 sites is out of range; allowed: [2, ${MAX_SITES}] sites`);
  assert.equal(msg('grid', { rows: 0, cols: 3, spacing_um: 4 }), 'grid rows: 0 is out of range; allowed: a whole number in [1, 400]');
  assert.equal(msg('line', { spacing_um: 4 }), 'line needs its sites');
  assert.equal(msg('line', { n: Number.NaN, spacing_um: 4 }), 'line sites: NaN is not a number');
  assert.equal(msg('star', {}), 'no preset "star"; allowed: line, grid, ring');
  assert.equal(msg('toString', {}), 'no preset "toString"; allowed: line, grid, ring');
});

test('every preset\'s defaults are valid, and its spec is the command line\'s', () => {
  for (const [kind, p] of Object.entries(PRESETS)) assert.ok(presetSites(kind, p.defaults, [50, 50]).length >= 2, kind);
  assert.equal(presetSpec('ring', { n: 6, radius_um: 8, angle_deg: 0 }), 'ring:n=6,radius_um=8');
  assert.equal(presetSpec('grid', { rows: 2, cols: 3, spacing_um: 5, angle_deg: 30 }), 'grid:rows=2,cols=3,spacing_um=5,angle_deg=30');
});
