// node --test: the protocol's words in people's words (src/words.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { phaseWords, hapticPhaseWords, replyWords, replyTitle } from '../src/words.js';

test('the strategy\'s phases in words, none with an underscore', () => {
  assert.equal(phaseWords('contact_search'), 'finding the particle\'s edge');
  assert.equal(phaseWords('park'), 'finding the substrate');
  assert.equal(phaseWords('to_parking_height'), 'rising to the parking height');
  assert.equal(phaseWords('preparing'), 'locating the particle and planning');
  for (const p of ['idle', 'scanning', 'preparing', 'stopped', 'travel', 'park', 'to_parking_height', 'let_go', 'contact_search', 'push', 'hold', 'back_off', 'retract', 'done']) {
    assert.doesNotMatch(phaseWords(p), /_/, p);
  }
});

test('a phase this page does not know is spaced; none is a dash', () => {
  assert.equal(phaseWords('new_phase'), 'new phase');
  assert.equal(phaseWords(null), '–');
  assert.equal(phaseWords('toString'), 'toString', 'an Object method\'s name is no phase');
});

test('the haptic phases in words', () => {
  assert.equal(hapticPhaseWords('park'), 'rising to the parking height');
  assert.equal(hapticPhaseWords('link_lost'), 'link lost: retracting');
  assert.equal(hapticPhaseWords('engaged'), 'engaged: the hand moves the tip');
  assert.equal(hapticPhaseWords(undefined), '–');
});

test('replies say what happened; the command number is the tooltip\'s', () => {
  assert.equal(replyWords({ status: 'pending' }), 'sending…');
  assert.equal(replyWords({ type: 'stop', status: 'ok' }), 'stop sent: the instrument stops');
  assert.equal(replyWords({ type: 'scan', status: 'ok' }), 'scan started');
  assert.equal(replyWords({ type: 'release_lease', status: 'ok' }), 'lease released');
  assert.equal(replyWords({ type: 'scan', status: 'error', code: 'busy', message: '' }), 'refused: busy');
  assert.doesNotMatch(replyWords({ id: 7, type: 'push', status: 'ok' }), /#7/);
  assert.equal(replyTitle({ id: 7, type: 'push', status: 'error', code: 'no_lease' }), 'command push #7 (no_lease)');
  assert.equal(replyTitle({ id: 8, type: 'scan', status: 'ok' }), 'command scan #8');
});
