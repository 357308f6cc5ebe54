// node --test: an assembly as the Session keeps it (src/assembly.js through src/session.js's
// handler table), over sequences of the server's assembly messages and a late joiner's state.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Session } from '../src/session.js';
import { siteState } from '../src/assembly.js';
import { planned, PLAN, SITES } from './fixtures/assembly.js';

const connected = () => {
  const s = new Session();
  s.opened();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: 4, scene: 'x', tick_hz: 1000 });
  return s;
};

test('a plan shows each site as planned, filled already or unreachable with its reason', () => {
  const s = connected();
  const ev = s.apply(planned());
  assert.equal(ev.kind, 'assembly');
  assert.equal(ev.what, 'planned');
  const a = s.state.assembly;
  assert.equal(a.phase, 'moving');
  assert.deepEqual([0, 1, 2].map((i) => siteState(a, i).state), ['planned', 'filled', 'unreachable']);
  assert.match(siteState(a, 2).reason, /no particle of the pattern's size/);
});

test('a plan names the full frame it was planned on, when the server recorded one', () => {
  const s = connected();
  s.apply(planned({ frame: 'scan-1-a-1.gsf' }));
  assert.equal(s.state.assembly.frame, 'scan-1-a-1.gsf');
  s.apply(planned({ assembly: 2, plan_only: true }));
  assert.equal(s.state.assembly.frame, null);
});

test('a move starts and ends, its site fills, the rest is planned again, then the end', () => {
  const s = connected();
  s.apply(planned());
  s.apply({ type: 'assembly_move_started', assembly: 1, number: 1, of: 1, planned: PLAN.moves[0], particle_id: 12 });
  const a = s.state.assembly;
  assert.deepEqual(a.moving, [1, 1]);
  assert.equal(a.particleId, 12);
  assert.equal(a.current.path.length, 3, 'the move running, with its path');
  s.apply({ type: 'assembly_move_ended', assembly: 1, number: 1, made: { purpose: 'fill', site: 0, particle: 12, outcome: 'ok', error: 8e-9, pushes: 1 } });
  assert.equal(a.moving, null);
  assert.equal(a.current, null);
  assert.equal(a.made.length, 1);
  assert.equal(siteState(a, 0).state, 'planned', 'not filled until the scan says so');
  s.apply({ type: 'assembly_site_filled', assembly: 1, site: 0 });
  s.apply({ type: 'assembly_site_filled', assembly: 1, site: 0 });
  assert.deepEqual(a.filled, [0], 'once');
  assert.equal(siteState(a, 0).state, 'filled');
  const rest = { ...PLAN, moves: [] };
  s.apply({ type: 'assembly_replanned', assembly: 1, plan: rest });
  assert.equal(a.plan, rest);
  const summary = { outcome: 'incomplete', sites: [{ target: SITES[0].target, status: 'filled' }, { target: SITES[1].target, status: 'filled' }, { target: SITES[2].target, status: 'unreachable', reason: 'no particle left' }], wall_time: 10, push_time: 8, scan_time: 4 };
  const ev = s.apply({ type: 'assembly_done', assembly: 1, outcome: 'incomplete', reason: null, summary, record: 'assembly-1.json' });
  assert.equal(ev.what, 'done');
  assert.equal(a.done.outcome, 'incomplete');
  assert.equal(a.done.record, 'assembly-1.json');
  assert.deepEqual(siteState(a, 2), { state: 'unreachable', reason: 'no particle left' }, 'the report\'s word at the end');
});

test('events of another assembly than the one shown change nothing', () => {
  const s = connected();
  s.apply(planned());
  assert.deepEqual(s.apply({ type: 'assembly_site_filled', assembly: 2, site: 2 }), { kind: 'assembly', what: 'stray', assembly: null });
  assert.deepEqual(s.state.assembly.filled, []);
  const fresh = new Session();
  assert.equal(fresh.apply({ type: 'assembly_move_started', assembly: 1, number: 1, of: 2 }).what, 'stray');
  assert.equal(fresh.state.assembly, null);
});

test('an end this page never saw start is shown from its report', () => {
  const s = connected();
  s.apply({ type: 'assembly_done', assembly: 5, outcome: 'refused', reason: 'no particle in the frame', summary: { pattern: 'ring', sites: [{ target: [1e-6, 2e-6], tolerance: 25e-9, status: 'refused', reason: 'no particle in the frame' }] } });
  const a = s.state.assembly;
  assert.equal(a.id, 5);
  assert.equal(a.sites.length, 1);
  assert.equal(siteState(a, 0).state, 'refused');
});

test('a late joiner\'s state redraws the assembly running: its plan, moves made, sites filled, the move running', () => {
  const s = connected();
  const now = { assembly: 3, by: 9, plan_only: false, pattern: 'sites', sites: SITES, phase: 'moving', plan: PLAN, moves: [{ purpose: 'fill', site: 1, outcome: 'ok' }], filled: [1], moving: [2, 3] };
  const ev = s.apply({ type: 'state', particles: [], stage: [0, 0, 0], phase: 'push', lease: 9, push: null, scan: null, assembly: now });
  assert.equal(ev.assemblyChanged, true);
  const a = s.state.assembly;
  assert.equal(a.id, 3);
  assert.equal(a.by, 9);
  assert.deepEqual(a.moving, [2, 3]);
  assert.equal(a.current, PLAN.moves[0], 'the move running is the first still to make');
  assert.equal(a.made.length, 1);
  assert.equal(siteState(a, 1).state, 'filled');
  // Away again, back to a state with none running: it ended unseen.
  s.apply({ type: 'state', particles: [], stage: [0, 0, 0], phase: 'idle', lease: null, push: null, scan: null, assembly: null });
  assert.equal(a.done.outcome, 'unseen');
  // A finished one stays as it was.
  const again = s.apply({ type: 'state', particles: [], stage: [0, 0, 0], phase: 'idle', lease: null, push: null, scan: null });
  assert.equal(again.assemblyChanged, false);
  assert.equal(s.state.assembly, a);
});

test('a plan-only assembly is planned, not moving', () => {
  const s = connected();
  s.apply(planned({ plan_only: true }));
  assert.equal(s.state.assembly.phase, 'planned');
  assert.equal(s.state.assembly.planOnly, true);
});
