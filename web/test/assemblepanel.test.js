// node --test: when the Assemble panel's Plan and Assemble may go, and why not in words
// (src/assemblepanel.js; the panel itself is tried in the browser: e2e/assembly.e2e.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Session } from '../src/session.js';
import { Pattern } from '../src/pattern.js';
import { assembleWhy } from '../src/assemblepanel.js';
import { planned } from './fixtures/assembly.js';

test('Plan and Assemble need the lease, an idle instrument and a site, said in words', () => {
  const s = new Session();
  const p = new Pattern(100);
  assert.equal(assembleWhy(s.state, p), 'Not connected to the server');
  s.opened();
  s.apply({ type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'x', tick_hz: 1000 });
  assert.equal(assembleWhy(s.state, p), 'Take the lease first');
  s.apply({ type: 'lease', holder: 4 });
  assert.match(assembleWhy(s.state, p), /^Place at least one site/);
  p.add(10, 10);
  assert.equal(assembleWhy(s.state, p), '');
  s.apply({ type: 'push_started', particle: 1, path: [[0, 0], [1e-6, 0]], by: 4 });
  assert.match(assembleWhy(s.state, p), /^The instrument is busy/);
  s.apply({ type: 'run_done', particle: 1, outcome: 'ok', estimate: [1e-6, 0] });
  s.apply(planned());
  assert.equal(assembleWhy(s.state, p), 'An assembly runs: Stop ends it');
  s.apply({ type: 'assembly_done', assembly: 1, outcome: 'stopped', reason: 'stopped: by the operator', summary: null });
  assert.equal(assembleWhy(s.state, p), '', 'after its end, another may go');
});

test('a real controller offers no assembly from the page: said before the lease', () => {
  const s = new Session();
  const p = new Pattern(100);
  p.add(10, 10);
  s.opened();
  s.apply({
    type: 'welcome', version: 1, client: 4, role: 'operator', lease: null, scene: 'x', tick_hz: 1000,
    instrument: { backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: [] },
  });
  const why = 'Assemblies from the page run on the simulated AFM; on this controller push each particle with nanopush push --instrument';
  assert.equal(assembleWhy(s.state, p), why, 'the lease would not help');
  s.apply({ type: 'lease', holder: 4 });
  assert.equal(assembleWhy(s.state, p), why);
});
