// node --test: an assembly in words (src/assemblyreport.js): its progress, its plan, its outcome
// and the final report, with no protocol words.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Session } from '../src/session.js';
import { progressText, planText, outcomeText, outcomeClass, reportRows, timesText, durationText, purposeWords, siteWords } from '../src/assemblyreport.js';
import { planned, PLAN } from './fixtures/assembly.js';

const session = () => {
  const s = new Session();
  s.apply(planned());
  return s;
};

test('the plan at a glance: moves, sites to fill, filled already, unreachable', () => {
  const a = session().state.assembly;
  assert.equal(planText(a), '1 move planned for 3 sites: 1 site to fill, 1 filled already, 1 cannot be reached');
  assert.equal(progressText(a), planText(a));
});

test('a plan-only assembly\'s end says its plan and that nothing moved', () => {
  const s = new Session();
  s.apply(planned({ plan_only: true }));
  s.apply({ type: 'assembly_done', assembly: 1, outcome: 'planned', reason: null, summary: null, record: null });
  assert.equal(progressText(s.state.assembly), '1 move planned for 3 sites: 1 site to fill, 1 filled already, 1 cannot be reached. Nothing moved: press Assemble to run it');
});

test('a move running says which of how many, the particle and what it does', () => {
  const s = session();
  s.apply({ type: 'assembly_move_started', assembly: 1, number: 2, of: 5, planned: PLAN.moves[0], particle_id: 12 });
  assert.equal(progressText(s.state.assembly), 'Move 2 of 5: #12 fills site 1');
  assert.equal(purposeWords({ purpose: 'clear' }), 'moves a particle the pattern does not need out of its way');
  assert.equal(purposeWords({ purpose: 'park' }), 'sets a particle aside until its site is free');
  s.apply({ type: 'assembly_move_ended', assembly: 1, number: 2, made: { outcome: 'ok' } });
  assert.match(progressText(s.state.assembly), /^Planning the rest from the last scan · /);
});

test('each outcome in words and colour, the reason without "stopped: " twice', () => {
  assert.equal(outcomeText({ outcome: 'filled' }), 'Assembled: every site holds a particle within its tolerance');
  assert.equal(outcomeText({ outcome: 'stopped', reason: 'stopped: stop requested by the operator' }), 'Stopped: stop requested by the operator');
  assert.equal(outcomeText({ outcome: 'refused', reason: 'two sites closer than 1.4 µm' }), 'Refused before anything moved: two sites closer than 1.4 µm');
  assert.equal(outcomeText({ outcome: 'planned' }), 'Planned: nothing moved. Press Assemble to run it');
  assert.equal(outcomeText({ outcome: 'deflection_limit', reason: 'x' }), 'Failed (deflection limit): x');
  assert.deepEqual(['filled', 'incomplete', 'stopped', 'refused'].map((o) => outcomeClass({ outcome: o })), ['good', 'warn', 'neutral', 'bad']);
  for (const o of ['filled', 'incomplete', 'refused', 'stopped', 'planned', 'unseen']) {
    assert.doesNotMatch(outcomeText({ outcome: o }), /_|incomplete|unreachable|plan_only/, o);
  }
});

test('the report: per site its state, error in nm and reason', () => {
  const rows = reportRows({
    sites: [
      { target: [40e-6, 40e-6], tolerance: 25e-9, particle: 3, measured: [40e-6 + 12e-9, 40e-6], error: 14e-9, status: 'filled', reason: null },
      { target: [44e-6, 40e-6], tolerance: 25e-9, particle: 5, measured: [44e-6, 40e-6 + 80e-9], error: null, status: 'missed', reason: 'still 80 nm away after 3 tries' },
      { target: [48e-6, 40e-6], tolerance: 25e-9, particle: null, measured: null, error: null, status: 'unreachable', reason: 'no clear path' },
    ],
  });
  assert.deepEqual(rows.map((r) => [r.site, r.state, r.particle, r.error, r.cls]), [
    [1, 'filled', '#3', '12.0 nm (true 14.0 nm)', 'good'],
    [2, 'missed: not within its tolerance', '#5', '80.0 nm', 'warn'],
    [3, 'cannot be reached', '–', '–', 'bad'],
  ]);
  assert.equal(rows[0].at, '(40.00, 40.00) µm');
  assert.equal(rows[2].reason, 'no clear path');
  assert.deepEqual(reportRows(null), []);
  assert.equal(siteWords('some_new_state'), 'some new state');
});

test('wall time against the instrument\'s simulated time', () => {
  assert.equal(timesText({ wall_time: 130, push_time: 120, scan_time: 65 }), 'Took 2 min 10 s for 3 min 5 s of the instrument\'s time (pushing 2 min 0 s, scanning 1 min 5 s)');
  assert.equal(durationText(0.85), '850 ms');
  assert.equal(durationText(4.25), '4.3 s');
  assert.equal(durationText(Number.NaN), '–');
});
