// node --test: the protocol's words in people's words (src/words.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { phaseWords, hapticPhaseWords, replyWords, replyTitle, instrumentText, instrumentTitle, notOfferedWhy, isSimulated } from '../src/words.js';
import { welcomeInstrument } from '../src/session.js';

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

const SIM = { backend: 'simulated AFM', feed_rate_hz: 1000, z_closed_locally: false, read_only: false, offers: ['push', 'scan', 'assemble', 'haptic'] };
const NANONIS = { backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: [] };

test('the instrument in a line: the simulated AFM, an older server, a real controller, read-only', () => {
  assert.equal(instrumentText(SIM), 'Simulated AFM · 1 kHz loop');
  assert.equal(instrumentText(SIM, { capital: false }), 'simulated AFM · 1 kHz loop', 'the Events log keeps the server\'s spelling');
  // An older server's welcome has no `instrument`: the simulated AFM at its tick rate.
  assert.equal(instrumentText(welcomeInstrument({ tick_hz: 1000 })), 'Simulated AFM · 1 kHz loop');
  assert.equal(instrumentText(welcomeInstrument({ tick_hz: 250 })), 'Simulated AFM · 250 Hz loop');
  assert.equal(instrumentText(welcomeInstrument({})), 'Simulated AFM', 'no rate said: none shown');
  assert.equal(instrumentText(NANONIS), 'Nanonis 127.0.0.1:6501 · signals at 1 kHz · force held by the controller');
  assert.equal(instrumentText({ ...NANONIS, feed_rate_hz: 1234.5, read_only: true }), 'Nanonis 127.0.0.1:6501 · signals at 1.23 kHz · force held by the controller · read-only');
  assert.equal(instrumentText({ ...NANONIS, z_closed_locally: false, feed_rate_hz: 40 }), 'Nanonis 127.0.0.1:6501 · signals at 40 Hz');
  assert.equal(instrumentText(null), '–', 'before the welcome');
  assert.ok(isSimulated(SIM) && !isSimulated(NANONIS) && !isSimulated(null));
});

test('the instrument\'s tooltip says what the page shows and what it does not offer', () => {
  assert.equal(instrumentTitle(SIM), 'The simulated AFM: the server\'s control loop runs it at 1 kHz, and the page shows its tip.');
  assert.equal(instrumentTitle({ ...NANONIS, read_only: true }),
    'A real controller (Nanonis 127.0.0.1:6501): the page shows its tip position and normal deflection, new readings at 1 kHz. '
    + 'Its own Z feedback holds the force on the tip. Read-only: nothing that moves the tip or changes Z is sent to it. '
    + 'Not offered from the page: push, scan, assemble, haptic handle; push with nanopush push --instrument, scan with nanopush scan --instrument.');
  assert.match(instrumentTitle(null), /has not said/);
});

test('a control the instrument does not offer: why, in words, with the command to use', () => {
  for (const k of ['push', 'scan', 'assemble', 'haptic']) {
    assert.equal(notOfferedWhy(SIM, k), '', k);
    assert.equal(notOfferedWhy(null, k), '', `${k}: not said yet, not refused here`);
  }
  assert.equal(notOfferedWhy(NANONIS, 'push'), 'Pushes from the page run on the simulated AFM; on this controller use nanopush push --instrument');
  assert.equal(notOfferedWhy(NANONIS, 'scan'), 'Scans from the page run on the simulated AFM; on this controller use nanopush scan --instrument');
  assert.match(notOfferedWhy(NANONIS, 'assemble'), /^Assemblies from the page run on the simulated AFM; on this controller push each particle with nanopush push --instrument$/);
  assert.equal(notOfferedWhy(NANONIS, 'haptic'), 'The haptic handle runs on the simulated AFM; on this controller it is off');
  assert.equal(notOfferedWhy({ ...SIM, offers: ['push'] }, 'scan'), 'Scans from the page run on the simulated AFM; on this controller use nanopush scan --instrument', 'each offer on its own');
});

test('a controller that offers scans names only the push for the command line', () => {
  const t = instrumentTitle({ backend: 'Nanonis 127.0.0.1:6501', feed_rate_hz: 1000, z_closed_locally: true, read_only: false, offers: ['scan'] });
  assert.match(t, /Not offered from the page: push, assemble, haptic handle; push with nanopush push --instrument\.$/);
});
