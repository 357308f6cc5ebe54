// node --test: the pattern's gestures on the map (src/siteeditor.js): click, drag, keys.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Pattern } from '../src/pattern.js';
import { SiteEditor } from '../src/siteeditor.js';

const setup = () => {
  const p = new Pattern(100);
  const said = [];
  const errors = [];
  const ed = new SiteEditor(p, { say: (t) => said.push(t), onError: (e) => errors.push(e.message) });
  return { p, ed, said, errors };
};

test('a click on an empty spot adds a site; off the stage it is refused in words', () => {
  const { p, ed, said, errors } = setup();
  assert.equal(ed.down(10, 10, 0.5), false, 'no site there: the press is not the editor\'s');
  assert.equal(ed.up(10, 10, true), true);
  assert.deepEqual(p.sites.map((s) => [s.x_um, s.y_um]), [[10, 10]]);
  assert.equal(said.at(-1), 'site 1 added at (10.00, 10.00) µm');
  assert.equal(ed.up(10, 10, false), false, 'a drag that was not on a site adds nothing');
  assert.equal(ed.up(null, null, true), false, 'off the map');
  ed.add(120, 10);
  assert.deepEqual(errors, ['a site at (120.00, 10.00) µm is off the stage; allowed: x and y in [0, 100] µm']);
  assert.equal(p.sites.length, 1);
});

test('a dragged site stays under the pointer; a preset moves whole', () => {
  const { p, ed, said } = setup();
  const ring = p.drop('ring', { n: 4, radius_um: 5 }, [50, 50]);
  assert.equal(ed.down(55.3, 50.2, 1), true, 'grabbed 0.3 µm right of site 1');
  assert.equal(p.selected, ring[0].id);
  ed.move(60.3, 40.2);
  ed.move(65.3, 45.2);
  assert.equal(ed.up(65.3, 45.2, false), true);
  assert.deepEqual([ring[0].x_um, ring[0].y_um].map((v) => Number(v.toFixed(9))), [65, 45]);
  assert.deepEqual([ring[2].x_um, ring[2].y_um].map((v) => Number(v.toFixed(9))), [55, 45], 'the ring\'s opposite site came along');
  assert.equal(said.at(-1), 'pattern moved: site 1 now at (65.00, 45.00) µm');
  assert.equal(ed.move(1, 1), false, 'no drag after the release');
});

test('a press and release on a site without moving selects it and adds nothing', () => {
  const { p, ed, said } = setup();
  const a = p.add(20, 20);
  p.add(30, 30);
  ed.down(20.1, 20, 0.5);
  ed.up(20.1, 20, true);
  assert.equal(p.sites.length, 2);
  assert.equal(p.selected, a.id);
  assert.equal(said.at(-1), 'site 1 selected, at (20.00, 20.00) µm');
});

test('by keyboard: Enter adds or selects, m moves, Delete removes', () => {
  const { p, ed, said } = setup();
  assert.equal(ed.key('Enter', [10, 10], 0.5), true);
  assert.equal(ed.key(' ', [20, 10], 0.5), true);
  assert.equal(p.sites.length, 2);
  ed.key('Enter', [10.2, 10], 0.5);
  assert.equal(p.selected, p.sites[0].id, 'Enter on a site selects it');
  ed.key('m', [15, 12], 0.5);
  assert.deepEqual([p.sites[0].x_um, p.sites[0].y_um], [15, 12]);
  assert.equal(said.at(-1), 'site 1 moved: site 1 now at (15.00, 12.00) µm');
  ed.key('Delete', [0, 0], 0.5);
  assert.equal(p.sites.length, 1);
  assert.equal(said.at(-1), 'site 1 removed; 1 left');
  ed.key('Backspace', [0, 0], 0.5);
  ed.key('Delete', [0, 0], 0.5);
  assert.equal(said.at(-1), 'no site selected to remove');
  assert.equal(ed.key('x', [0, 0], 0.5), false, 'other keys are the map\'s');
});
