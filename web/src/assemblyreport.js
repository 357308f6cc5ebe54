// An assembly in people's words, no DOM: where it stands (planning, move k of n and what it
// does, the plan at a glance), each site's state, and the final report (per site: filled,
// missed or unreachable, its error in nm, the reason; the outcome; wall time against simulated
// time). The protocol's words (`fill`, `incomplete`, `unreachable`) never show as such. Runs in
// Node (tests).
import { formatPoint } from './format.js';
import { siteState } from './assembly.js';

/** A site's state in words. */
const SITE_WORDS = Object.freeze({
  filled: 'filled',
  planned: 'to be filled',
  open: 'open',
  missed: 'missed: not within its tolerance',
  unreachable: 'cannot be reached',
  refused: 'refused',
});

export function siteWords(state) {
  return Object.hasOwn(SITE_WORDS, state) ? SITE_WORDS[state] : String(state).replace(/_/g, ' ');
}

/** What a move does, in words: `fills site 3`, `moves a particle out of the pattern's way`. */
export function purposeWords(move) {
  if (move.purpose === 'fill') return `fills site ${(move.site ?? 0) + 1}`;
  if (move.purpose === 'clear') return 'moves a particle the pattern does not need out of its way';
  if (move.purpose === 'park') return 'sets a particle aside until its site is free';
  return String(move.purpose).replace(/_/g, ' ');
}

/** The plan at a glance: `9 moves planned: 8 sites to fill, 1 filled already, 1 cannot be reached`. */
export function planText(a) {
  const n = a.sites.length;
  const counts = {};
  for (let i = 0; i < n; i++) {
    const st = siteState(a, i).state;
    counts[st] = (counts[st] ?? 0) + 1;
  }
  const moves = a.plan?.moves?.length ?? 0;
  const parts = [];
  if (counts.planned) parts.push(`${counts.planned} site${counts.planned === 1 ? '' : 's'} to fill`);
  if (counts.filled) parts.push(`${counts.filled} filled already`);
  for (const k of ['unreachable', 'refused', 'missed']) if (counts[k]) parts.push(`${counts[k]} ${k === 'unreachable' ? 'cannot be reached' : siteWords(k).split(':')[0]}`);
  return `${moves} move${moves === 1 ? '' : 's'} planned for ${n} site${n === 1 ? '' : 's'}${parts.length ? `: ${parts.join(', ')}` : ''}`;
}

/** Where the assembly stands, in one line. */
export function progressText(a) {
  if (a.done?.outcome === 'planned') return `${planText(a)}. Nothing moved: press Assemble to run it`;
  if (a.done) return outcomeText(a.done);
  if (a.moving) {
    const [k, n] = a.moving;
    const what = a.current ? `: #${a.particleId ?? '?'} ${purposeWords(a.current)}` : '';
    return `Move ${k} of ${n}${what}`;
  }
  if (a.phase === 'planning' || !a.plan) return 'Planning: a full frame of the stage finds the particles';
  if (a.phase === 'replanning') return `Planning the rest from the last scan · ${planText(a)}`;
  if (a.phase === 'judging') return 'Judging: a full frame of the stage checks every site';
  return planText(a);
}

/** The outcome in words, with the reason when there is one. */
export function outcomeText(d) {
  const why = d.reason ? `: ${String(d.reason).replace(/^stopped: /, '')}` : '';
  switch (d.outcome) {
    case 'filled': return 'Assembled: every site holds a particle within its tolerance';
    case 'incomplete': return 'Finished with sites left open (see each site below)';
    case 'refused': return `Refused before anything moved${why}`;
    case 'stopped': return `Stopped${why}`;
    case 'planned': return 'Planned: nothing moved. Press Assemble to run it';
    case 'unseen': return 'It ended while this page was away: its record under Records says how';
    default: return `Failed (${String(d.outcome).replace(/_/g, ' ')})${why}`;
  }
}

/** The colour of an outcome: good, neutral (stopped, planned), warn (sites left), bad. */
export function outcomeClass(d) {
  return { filled: 'good', stopped: 'neutral', planned: 'neutral', unseen: 'neutral', incomplete: 'warn' }[d.outcome] ?? 'bad';
}

const nm = (m) => `${(m * 1e9).toFixed(1)} nm`;

/** A duration (s) in words: `850 ms`, `42 s`, `3 min 5 s`. */
export function durationText(s) {
  if (!Number.isFinite(s)) return '–';
  if (s < 1) return `${Math.round(s * 1000)} ms`;
  if (s < 60) return `${s.toFixed(s < 10 ? 1 : 0)} s`;
  const m = Math.floor(s / 60);
  return `${m} min ${Math.round(s - 60 * m)} s`;
}

/** Wall time against simulated time: `took 2 min 10 s for 3 min 5 s of simulated work (pushes …, scans …)`. */
export function timesText(summary) {
  const sim = summary.push_time + summary.scan_time;
  return `Took ${durationText(summary.wall_time)} for ${durationText(sim)} of the instrument's time (pushing ${durationText(summary.push_time)}, scanning ${durationText(summary.scan_time)})`;
}

/**
 * One row a site of the final report (`summary.sites[i]`, SI): its number, where it is, its
 * state in words, its error (measured by the last full frame; the simulation's true error when
 * the report has it) and why it is not filled.
 */
export function reportRows(summary) {
  return (summary?.sites ?? []).map((s, i) => {
    const measured = Array.isArray(s.measured) ? Math.hypot(s.measured[0] - s.target[0], s.measured[1] - s.target[1]) : null;
    const error = measured === null ? '–' : `${nm(measured)}${Number.isFinite(s.error) ? ` (true ${nm(s.error)})` : ''}`;
    return {
      site: i + 1,
      at: formatPoint(s.target),
      state: siteWords(s.status),
      cls: s.status === 'filled' ? 'good' : s.status === 'missed' ? 'warn' : 'bad',
      particle: s.particle === null || s.particle === undefined ? '–' : `#${s.particle}`,
      error,
      reason: s.reason ?? '',
    };
  });
}

/**
 * An assembly event (the Session's `{kind: 'assembly', what, assembly}`) for the event log, in
 * words, with its colour; null for what the log does not say (a new plan after each move: the
 * progress line says it; an event of an assembly this page does not know).
 */
export function assemblyLogLine(ev, client) {
  const a = ev.assembly;
  if (!a) return null;
  const who = a.by === null ? '' : a.by === client ? ' (yours)' : ` (client ${a.by})`;
  switch (ev.what) {
    case 'planned':
      return { text: `assembly ${a.id}${who} ${a.planOnly ? 'planned, to look at' : 'planned'}: ${planText(a)}`, cls: 'neutral' };
    case 'move_started':
      return { text: `assembly ${a.id}: ${progressText(a).replace(/^Move/, 'move')}`, cls: 'neutral' };
    case 'move_ended': {
      const m = a.made[a.made.length - 1];
      if (!m) return null;
      const how = m.outcome === 'ok' ? 'on target' : m.outcome === 'missed' ? 'missed its target' : String(m.outcome).replace(/_/g, ' ');
      const err = Number.isFinite(m.error) ? `, ${nm(m.error)} from it` : '';
      return { text: `assembly ${a.id}: move ${a.made.length} ended ${how}${err}`, cls: m.outcome === 'ok' ? 'good' : 'warn' };
    }
    case 'site_filled':
      return { text: `assembly ${a.id}: site ${a.filled[a.filled.length - 1] + 1} filled`, cls: 'good' };
    case 'done':
      return { text: `assembly ${a.id}: ${progressText(a)}`, cls: outcomeClass(a.done) };
    default:
      return null;
  }
}
