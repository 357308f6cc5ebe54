// node --test: what runs now and how the last push ended (src/pushstatus.js): the push's progress
// against its plan, and the texts.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { pathLength, travelAlong, pushProgress, progressText, pushNowText, lostNowText, PushStatus } from '../src/pushstatus.js';

const near = (a, b, what) => assert.ok(Math.abs(a - b) < 1e-12, `${what}: ${a} vs ${b}`);

test('a path of legs 3 and 4 µm is 7 µm long', () => {
  near(pathLength([[0, 0], [3e-6, 0], [3e-6, 4e-6]]), 7e-6, 'length');
  assert.equal(pathLength([[1, 1]]), 0);
  assert.equal(pathLength(null), 0);
});

test('travel along the path: the estimate\'s nearest point, along the legs', () => {
  const path = [[0, 0], [3e-6, 0], [3e-6, 4e-6]];
  near(travelAlong(path, [1e-6, 0.2e-6]), 1e-6, 'abreast of 1 µm on the first leg');
  near(travelAlong(path, [3.1e-6, 2e-6]), 5e-6, 'half-way up the second leg');
  near(travelAlong(path, [-1e-6, 0]), 0, 'behind the start');
  near(travelAlong(path, [3e-6, 9e-6]), 7e-6, 'past the end');
  assert.equal(travelAlong(path, null), 0, 'no estimate yet');
});

test('a 5 µm push at 2 µm/s, 2 µm done: 3 µm and 1.5 s left', () => {
  const pr = pushProgress({ path: [[40e-6, 30e-6], [45e-6, 30e-6]] }, [42e-6, 30.05e-6], 2e-6);
  near(pr.doneM, 2e-6, 'done');
  near(pr.totalM, 5e-6, 'total');
  near(pr.leftS, 1.5, 'left');
  assert.equal(progressText(pr, 'contact_search'), '2.00 of 5.00 µm · about 2 s of pushing left · finding the particle\'s edge');
  assert.equal(pushProgress({ path: [[0, 0], [1e-6, 0]] }, null, null).leftS, null, 'no speed: no time');
  assert.equal(progressText({ doneM: 5e-6, totalM: 5e-6, leftS: 0 }, 'retract'), '5.00 of 5.00 µm · pushed · retracting the tip');
  assert.equal(progressText({ doneM: 0, totalM: 5e-6, leftS: null }, null), '0.00 of 5.00 µm');
});

test('the push running and the one lost with the connection, in words', () => {
  const push = { particle: 1, path: [[40e-6, 30e-6], [45e-6, 30e-6], [45e-6, 32.5e-6]], by: 9 };
  assert.equal(pushNowText(push, 9), 'Pushing #1 (you) to (45.000, 32.500) µm');
  assert.equal(pushNowText(push, 4), 'Pushing #1 (client 9) to (45.000, 32.500) µm');
  assert.equal(lostNowText(push, 9), 'Push of #1 (you): outcome unknown until the server is back (the connection closed while it ran)');
});

/** The box's elements as plain objects, and a frame loop that draws at once. */
function box(state) {
  const els = {};
  const $ = (id) => (els[id] ??= { id, hidden: id === 'push-now' || id === 'lastrun', textContent: '', className: '', value: 0, max: 1 });
  const scheduler = { register: (name, draw) => ({ mark: () => draw() }) };
  return { els, status: new PushStatus($, scheduler, { state: () => state, speed: () => 2e-6 }) };
}

test('one at a time: the push running hides the last run, its end shows it', () => {
  const st = { connection: 'open', client: 9, push: null, lostPush: null, tip: null, phase: 'idle' };
  const { els, status } = box(st);
  status.showRun('push of #1 ok', 'good');
  assert.equal(els.lastrun.hidden, false);
  assert.equal(els['push-now'].hidden, true);
  st.push = { particle: 1, path: [[0, 0], [4e-6, 0]], by: 9 };
  st.tip = { estimate: [1e-6, 0] };
  st.phase = 'push';
  status.render();
  assert.equal(els.lastrun.hidden, true, 'the last run waits while a push runs');
  assert.equal(els['push-now'].hidden, false);
  assert.equal(els['push-progress'].textContent, '1.00 of 4.00 µm · about 2 s of pushing left · pushing');
  assert.ok(Math.abs(els['push-bar'].value - 1) < 1e-9 && Math.abs(els['push-bar'].max - 4) < 1e-9, 'the bar in µm');
  st.push = null;
  status.showRun('push of #1 stopped', 'neutral');
  assert.deepEqual([els.lastrun.hidden, els['push-now'].hidden, els.lastrun.className], [false, true, 'lastrun neutral']);
});

test('a push lost with the connection is unknown until the server is back', () => {
  const st = { connection: 'closed', client: null, push: null, lostPush: { particle: 2, path: [[0, 0], [1e-6, 0]], by: 5 }, tip: null };
  const { els, status } = box(st);
  status.closed(5);
  assert.equal(els['push-now'].hidden, false);
  assert.equal(els['push-now'].className, 'push-now unknown');
  assert.match(els['push-now-text'].textContent, /^Push of #2 \(you\): outcome unknown until the server is back/);
  assert.equal(els['push-bar'].hidden, true);
  st.connection = 'open';
  st.lostPush = null;
  status.showRun('push of #2 ended while this page was away: stopped', 'neutral');
  assert.equal(els['push-now'].hidden, true, 'settled: the last run says how it ended');
  assert.equal(els.lastrun.hidden, false);
});
