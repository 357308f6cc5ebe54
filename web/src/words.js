// The protocol's words put in people's words, no DOM: the instrument's phases (telemetry's and
// `state`'s `phase`: idle, scanning, preparing and the push strategy's phases of Fig 2), the
// haptic z-control's phases, and what a command's reply means. The page and the monitor show
// these; the protocol's own names stay in the tooltips and the CSV, for whoever reads the logs.
// And the instrument behind the server (`welcome`'s `instrument`): its backend and rate, and why
// a control it does not offer is off.
import { rateText } from './devicefaults.js';

/** The instrument's phases (server/src/app_state.rs, the strategy's `Phase::name`). */
const PHASES = Object.freeze({
  idle: 'idle',
  scanning: 'scanning',
  preparing: 'locating the particle and planning',
  stopped: 'stopped',
  travel: 'travelling to the start',
  park: 'finding the substrate',
  to_parking_height: 'rising to the parking height',
  let_go: 'freeing the tip from the substrate',
  contact_search: 'finding the particle\'s edge',
  push: 'pushing',
  hold: 'letting the particle settle',
  back_off: 'backing away from the particle',
  retract: 'retracting the tip',
  done: 'done',
});

/** The haptic z-control's phases (instrument/src/control/bilateral.rs, `Phase::name`). */
const HAPTIC_PHASES = Object.freeze({
  off: 'off',
  approach: 'finding the surface',
  park: 'rising to the parking height',
  settle: 'waiting for the force to settle',
  ramp: 'force ramping in',
  engaged: 'engaged: the hand moves the tip',
  clutched: 'clutched: the hand re-centres',
  pushing: 'a push runs: the hand feels it',
  link_lost: 'link lost: retracting',
  retract: 'retracting',
});

const spaced = (name) => String(name).replace(/_/g, ' ');

/** An instrument phase in words ('–' when unknown; a phase this page does not know, spaced). */
export function phaseWords(phase) {
  if (phase === null || phase === undefined) return '–';
  return Object.hasOwn(PHASES, phase) ? PHASES[phase] : spaced(phase);
}

/** A haptic phase in words. */
export function hapticPhaseWords(phase) {
  if (phase === null || phase === undefined) return '–';
  return Object.hasOwn(HAPTIC_PHASES, phase) ? HAPTIC_PHASES[phase] : spaced(phase);
}

/** What each command's `ok` means, said to the person who sent it. */
const DONE = Object.freeze({
  take_lease: 'lease taken',
  release_lease: 'lease released',
  push: 'push accepted: running',
  scan: 'scan started',
  assemble: 'accepted: a full frame, then the plan',
  stop: 'stop sent: the instrument stops',
  haptic: 'done',
  subscribe: 'subscribed',
});

/**
 * A command's reply in words (the Session's command record: {id, type, status, code, message}):
 * "lease taken", "push accepted: running", "refused: push needs the lease"; "sending…" while
 * pending. The command's number stays out of the text: it is the tooltip's (`replyTitle`).
 */
export function replyWords(c) {
  if (c.status === 'pending') return 'sending…';
  if (c.status === 'ok') return DONE[c.type] ?? 'done';
  if (c.code === 'disconnected') return 'no answer: the connection closed before the server replied';
  return `refused: ${c.message || spaced(c.code)}`;
}

/** The reply's tooltip: the command and its number, the code of a refusal, for the logs. */
export function replyTitle(c) {
  return `command ${c.type} #${c.id}${c.status === 'error' && c.code ? ` (${c.code})` : ''}`;
}

/** Whether the instrument is the server's simulated AFM (else a real controller). */
export function isSimulated(inst) {
  return /^simulated\b/i.test(inst?.backend ?? '');
}

/**
 * The instrument in a line (the Session's `instrument`): "Simulated AFM · 1 kHz loop", "Nanonis
 * 127.0.0.1:6501 · signals at 1 kHz · force held by the controller · read-only"; '–' before the
 * server said. `capital: false` keeps the backend as the server writes it (the Events log).
 */
export function instrumentText(inst, { capital = true } = {}) {
  if (!inst) return '–';
  const name = capital ? inst.backend.charAt(0).toUpperCase() + inst.backend.slice(1) : inst.backend;
  const rate = rateText(inst.feed_rate_hz);
  const parts = [name];
  if (rate) parts.push(isSimulated(inst) ? `${rate} loop` : `signals at ${rate}`);
  if (inst.z_closed_locally) parts.push('force held by the controller');
  if (inst.read_only) parts.push('read-only');
  return parts.join(' · ');
}

/** The controls by `offers` name, as people call them. */
const OFFER_NAMES = Object.freeze({ push: 'push', scan: 'scan', assemble: 'assemble', haptic: 'haptic handle' });

/** The instrument line's tooltip: what the page shows of it, what it does not offer, and why. */
export function instrumentTitle(inst) {
  if (!inst) return 'The server has not said which instrument it drives yet';
  const rate = rateText(inst.feed_rate_hz) ?? 'an unknown rate';
  const head = isSimulated(inst)
    ? `The simulated AFM: the server's control loop runs it at ${rate}, and the page shows its tip.`
    : `A real controller (${inst.backend}): the page shows its tip position and normal deflection, new readings at ${rate}.`;
  const parts = [head];
  if (inst.z_closed_locally) parts.push('Its own Z feedback holds the force on the tip.');
  if (inst.read_only) parts.push('Read-only: nothing that moves the tip or changes Z is sent to it.');
  const missing = Object.keys(OFFER_NAMES).filter((k) => !inst.offers.includes(k));
  if (missing.length) {
    const cli = ['push', 'scan'].filter((k) => missing.includes(k)).map((k) => `${k} with nanopush ${k} --instrument`);
    parts.push(`Not offered from the page: ${missing.map((k) => OFFER_NAMES[k]).join(', ')}${cli.length ? `; ${cli.join(', ')}` : ''}.`);
  }
  return parts.join(' ');
}

/** Why a control the instrument does not offer is off (`what`: an `offers` name), in words. */
const NOT_OFFERED = Object.freeze({
  push: 'Pushes from the page run on the simulated AFM; on this controller use nanopush push --instrument',
  scan: 'Scans from the page run on the simulated AFM; on this controller use nanopush scan --instrument',
  assemble: 'Assemblies from the page run on the simulated AFM; on this controller push each particle with nanopush push --instrument',
  haptic: 'The haptic handle runs on the simulated AFM; on this controller it is off',
});

/** '' when the instrument offers `what` (or the server has not said), else why not. */
export function notOfferedWhy(inst, what) {
  if (!inst || inst.offers.includes(what)) return '';
  return NOT_OFFERED[what] ?? `${spaced(what)} is not offered on this instrument`;
}
