// The protocol's words put in people's words, no DOM: the instrument's phases (telemetry's and
// `state`'s `phase`: idle, scanning, preparing and the push strategy's phases of Fig 2), the
// haptic z-control's phases, and what a command's reply means. The page and the monitor show
// these; the protocol's own names stay in the tooltips and the CSV, for whoever reads the logs.

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
