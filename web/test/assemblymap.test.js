// node --test: what the map draws of an assembly (src/assemblymap.js: the views; its SVG is not
// built here).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Session } from '../src/session.js';
import { Pattern } from '../src/pattern.js';
import { patternView, assemblyView, siteTitle } from '../src/assemblymap.js';
import { planned, PLAN } from './fixtures/assembly.js';

test('the pattern being drawn: sites in metres, its tolerance, the selected one marked', () => {
  const p = new Pattern(100);
  p.add(10, 20);
  const b = p.add(30, 40);
  let v = patternView(p, 25);
  assert.deepEqual(v.sites.map((s) => [s.x, s.y, s.n, s.state, s.selected]), [[10e-6, 20e-6, 1, 'draft', false], [30e-6, 40e-6, 2, 'draft', true]]);
  assert.equal(v.sites[0].tol, 25e-9, 'the server\'s default when the pattern gives none');
  p.setTolerance(60);
  v = patternView(p, 25);
  assert.equal(v.sites[1].tol, 60e-9);
  assert.equal(b.id, p.selected);
  assert.deepEqual([v.assign, v.paths, v.current], [[], [], null]);
});

test('a plan: each planned site tied to its particle, each move\'s path, the move running highlighted', () => {
  const s = new Session();
  s.apply(planned());
  let v = assemblyView(s.state.assembly);
  assert.deepEqual(v.sites.map((x) => x.state), ['planned', 'filled', 'unreachable']);
  assert.deepEqual(v.assign, [[[PLAN.map[1].x, PLAN.map[1].y], PLAN.moves[0].to]], 'particle 1 → site 1 only: site 2 holds one already');
  assert.deepEqual(v.paths, [{ pts: PLAN.moves[0].path, purpose: 'fill' }]);
  assert.equal(v.current, null);
  s.apply({ type: 'assembly_move_started', assembly: 1, number: 1, of: 1, planned: PLAN.moves[0], particle_id: 12 });
  v = assemblyView(s.state.assembly);
  assert.equal(v.current, PLAN.moves[0].path);
  s.apply({ type: 'assembly_done', assembly: 1, outcome: 'stopped', reason: 'stopped: by the operator', summary: null });
  v = assemblyView(s.state.assembly);
  assert.deepEqual([v.assign, v.paths, v.current], [[], [], null], 'once done only the sites stay');
});

test('a plan-only assembly\'s end leaves its plan drawn', () => {
  const s = new Session();
  s.apply(planned({ plan_only: true }));
  s.apply({ type: 'assembly_done', assembly: 1, outcome: 'planned', reason: null, summary: null, record: null });
  const v = assemblyView(s.state.assembly);
  assert.equal(v.paths.length, 1);
  assert.equal(v.assign.length, 1);
  assert.deepEqual(v.sites.map((x) => x.state), ['planned', 'filled', 'unreachable']);
});

test('a site\'s tooltip says its state and reason in words', () => {
  assert.equal(siteTitle({ n: 3, state: 'unreachable', reason: 'no clear path' }), 'site 3: cannot be reached (no clear path)');
  assert.equal(siteTitle({ n: 1, state: 'draft', reason: null }), 'site 1: in the pattern');
  assert.equal(siteTitle({ n: 2, state: 'filled', reason: null }), 'site 2: filled');
});
