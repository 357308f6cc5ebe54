// node --test: the pattern being drawn (src/pattern.js): sites added, dragged, deleted, presets
// dropped and dragged as a whole, kept on the stage, and its refusals in words.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Pattern } from '../src/pattern.js';

const xy = (p) => p.sites.map((s) => [Number(s.x_um.toFixed(6)), Number(s.y_um.toFixed(6))]);

test('a click adds a site and selects it; a site off the stage is refused in words', () => {
  const p = new Pattern(100);
  const s = p.add(10, 20);
  assert.equal(p.selected, s.id);
  assert.deepEqual(xy(p), [[10, 20]]);
  assert.throws(() => p.add(101, 5), { message: 'a site at (101.00, 5.00) µm is off the stage; allowed: x and y in [0, 100] µm' });
  assert.throws(() => p.add(Number.NaN, 5), /off the stage/);
  assert.equal(p.sites.length, 1, 'nothing added by a refusal');
});

test('a dropped preset is one group: dragging any of its sites moves them all', () => {
  const p = new Pattern(100);
  const lone = p.add(5, 5);
  const ring = p.drop('ring', { n: 4, radius_um: 6 }, [50, 50]);
  assert.equal(p.selected, ring[0].id);
  assert.deepEqual(p.moveBy(ring[2].id, 10, -5), [10, -5]);
  assert.deepEqual(xy(p), [[5, 5], [66, 45], [60, 51], [54, 45], [60, 39]]);
  p.moveBy(lone.id, 1, 1);
  assert.deepEqual(xy(p)[0], [6, 6], 'a lone site moves alone');
  assert.deepEqual(xy(p)[1], [66, 45], '… and not the ring');
});

test('a drag past the stage\'s edge stops the whole preset there', () => {
  const p = new Pattern(100);
  const line = p.drop('line', { n: 3, spacing_um: 4 }, [90, 50]);
  assert.deepEqual(p.moveBy(line[0].id, 20, 0), [6, 0], 'its right end stops at 100 µm');
  assert.deepEqual(xy(p), [[92, 50], [96, 50], [100, 50]]);
  assert.deepEqual(p.moveBy(line[0].id, 0, -80), [0, -50]);
});

test('a preset that would leave the stage, or overfill the pattern, adds nothing', () => {
  const p = new Pattern(100);
  assert.throws(() => p.drop('line', { n: 5, spacing_um: 10 }, [90, 50]), { message: 'line site 5 at (110.00, 50.00) µm is off the stage; allowed: x and y in [0, 100] µm' });
  assert.equal(p.sites.length, 0);
  p.drop('grid', { rows: 20, cols: 20, spacing_um: 0.2 }, [50, 50]);
  assert.throws(() => p.add(1, 1), { message: '401 sites; allowed: at most 400 in a pattern' });
  assert.throws(() => p.drop('line', { n: 0, spacing_um: 1 }, [50, 50]), /line sites: 0 is out of range; allowed: a whole number in \[2, 400\]/);
});

test('delete removes a site, selects the next, and unnames a short preset', () => {
  const p = new Pattern(100);
  const ring = p.drop('ring', { n: 3, radius_um: 5 }, [50, 50]);
  assert.equal(p.name(), 'ring:n=3,radius_um=5');
  p.moveBy(ring[0].id, 1, 0);
  assert.equal(p.name(), 'ring:n=3,radius_um=5', 'moved, it is still the ring');
  assert.equal(p.remove(ring[1].id), true);
  assert.equal(p.selected, ring[2].id);
  assert.equal(p.name(), '2 sites');
  p.remove(ring[2].id);
  assert.equal(p.selected, ring[0].id, 'the last removed: the one before');
  assert.equal(p.remove(999), false);
  p.remove(ring[0].id);
  assert.equal(p.selected, null);
  assert.equal(p.groups.size, 0, 'an emptied preset is forgotten');
});

test('a site typed in its fields leaves its preset and is checked on the stage', () => {
  const p = new Pattern(50);
  const line = p.drop('line', { n: 2, spacing_um: 4 }, [25, 25]);
  p.place(line[1].id, 30, 30);
  assert.equal(p.site(line[1].id).group, null);
  p.moveBy(line[0].id, 1, 0);
  assert.deepEqual(xy(p), [[24, 25], [30, 30]], 'the other site moves alone now');
  assert.throws(() => p.place(line[0].id, 60, 1), { message: 'site 1 at (60.00, 1.00) µm is off the stage; allowed: x and y in [0, 50] µm' });
});

test('the site under a point is the nearest within its ring', () => {
  const p = new Pattern(100);
  p.add(10, 10);
  const b = p.add(11, 10);
  assert.equal(p.siteAt(10.7, 10, 1).id, b.id);
  assert.equal(p.siteAt(20, 20, 1), null);
});

test('the tolerance is empty (the server\'s) or within [1, 100000] nm', () => {
  const p = new Pattern(100);
  p.setTolerance(50);
  assert.equal(p.toleranceNm, 50);
  p.setTolerance(undefined);
  assert.equal(p.toleranceNm, undefined);
  assert.throws(() => p.setTolerance(0.5), { message: 'tolerance 0.5 nm is out of range; allowed: [1, 100000] nm' });
  assert.throws(() => p.setTolerance(Number.NaN), /out of range/);
});
