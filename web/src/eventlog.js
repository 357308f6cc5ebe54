// The event log (the newest 60 lines, newest first, each with its time) and the screen-reader
// announcements (only what matters: runs, the lease, shutdown). The texts of the server's
// events are pure functions of the event and the Session's state (Node tests).
import { formatLength, formatStagePoint } from './format.js';
import { holderText } from './session.js';
import { instrumentText } from './words.js';

/** Lines the log keeps. */
export const LOG_LINES = 60;

/**
 * Said when the connection closes while this page holds the lease and no push runs. The page
 * cannot tell a network gone from a server gone: what a running server does is said as such.
 */
export const LEASE_LOST_ON_CLOSE = 'you lost the lease: the connection closed (a server still running frees it and stops the scan its holder ran); take it again once reconnected';

/**
 * Said when the connection closes while a push runs (`push`: the Session's, `hadLease`: this
 * page held the lease): its outcome is unknown until the server is back.
 */
export function lostOnCloseText(push, hadLease) {
  const head = `the connection closed while the push of #${push.particle} ran: its outcome is unknown until the server is back`;
  return hadLease
    ? `${head}. You lost the lease with the connection: a server still running stops a push whose lease holder is gone, and a server that stopped stopped it; take the lease again once reconnected`
    : head;
}

/** The server's `welcome`: who this page is, the scene, the instrument (backend and rate). */
export function welcomeText(st) {
  return `welcome: client ${st.client}${st.name ? ` (${st.name})` : ''}, ${st.role}, scene ${st.scene}, ${instrumentText(st.instrument, { capital: false })}`;
}

/** The server's `state` after a (re)connect, in one line. */
export function stateText(st) {
  return `state: phase ${st.phase ?? '–'}, ${st.lease === null ? 'lease free' : `lease held by ${holderText(st)}`}${st.push ? `, pushing #${st.push.particle}` : ''}${st.scan ? `, latest scan ${st.scan.record ?? st.scan.id}${st.scanStale ? ' (stale)' : ''}` : ''}`;
}

/** A scan (the Session's, or a parsed record) by its size: `…: 32×32 px, 10.0 µm square`. */
export function scanSize(sc) {
  return `${sc.xres}×${sc.yres} px, ${formatLength(sc.x_real)} square`;
}

/** A `scan_done` event: {text, cls}. */
export function scanDoneNote(ev) {
  return {
    text: ev.record ? `scan done: ${ev.record}` : ev.record_error ? `scan done, no record: ${ev.record_error}` : 'scan cancelled',
    cls: ev.record ? 'good' : 'bad',
  };
}

/** Who runs a push, for this client: `you` or `client N`. */
export function pusher(push, client) {
  return push.by === client ? 'you' : `client ${push.by}`;
}

export function pushStartedText(push, client) {
  const end = push.path[push.path.length - 1];
  const legs = `${push.path.length - 1} leg${push.path.length > 2 ? 's' : ''}`;
  if (push.attempt > 1) {
    return `correction ${push.attempt - 1} of #${push.particle}: the scan after the push found it outside the tolerance; pushing it from ${formatStagePoint(push.path[0])} to ${formatStagePoint(end)} in ${legs}`;
  }
  return `push started: #${push.particle} by ${pusher(push, client)}, to ${formatStagePoint(end)} in ${legs}`;
}

/**
 * The strategy the plan chose for a push and what it tried first (`push_started`'s `strategy`),
 * one line each: said when a move's first push starts.
 */
export function pushStrategy(push) {
  const st = push?.strategy;
  if (!st || typeof st.summary !== 'string') return [];
  const tried = Array.isArray(st.tried) ? st.tried.filter((t) => typeof t === 'string') : [];
  return [`strategy for #${push.particle}: ${st.summary}`, ...tried.map((t) => `  tried first: ${t}`)];
}

/** What the strategy plan warns of for a push (`push_started`'s `warnings`), one line each. */
export function pushWarnings(push) {
  return Array.isArray(push?.warnings) ? push.warnings.map((w) => `plan warning for #${push.particle}: ${w}`) : [];
}

/** A `lease` event: {text, cls, announce} (`announce`: what to tell a screen reader, or null). */
export function leaseNote(ev, st) {
  const now = st.lease === null ? 'the lease is free' : st.lease === st.client ? 'you hold the lease' : `${holderText(st)} holds the lease`;
  if (ev.lost) {
    const t = `you lost the lease: ${ev.reason ?? now}`;
    return { text: t, cls: 'bad', announce: t };
  }
  return { text: ev.reason ? `${now}: ${ev.reason}` : now, cls: ev.reason ? 'bad' : '', announce: ev.reason ?? null };
}

/** A reply `error` (`e` is the Session's lastError). */
export function replyErrorText(ev, e) {
  return `error${ev.id !== null ? ` #${ev.id}` : ''} ${e.code}: ${e.message}`;
}

export function closedText(ev) {
  if (ev.code === null || ev.code === undefined) return `connection closed (${ev.reason || 'no reason'})`;
  return `connection closed (code ${ev.code}${ev.reason ? `, ${ev.reason}` : ''})`;
}

/** HH:MM:SS of a Unix time (ms), in the page's time zone. */
export function clockTime(ms) {
  return new Date(ms).toLocaleTimeString([], { hour: '2-digit', minute: '2-digit', second: '2-digit', hour12: false });
}

/** The server restarted while this page was away: when the new one started. */
export function restartText(startedUnixMs) {
  return `the server restarted (this run started at ${startedUnixMs ? clockTime(startedUnixMs) : 'an unknown time'}): what this page showed before is gone`;
}

/**
 * The push that ran when the connection closed, and was never seen to end: `run` is its
 * record's entry in /api/runs (the same server, a newer record of that particle), or null.
 */
export function lostPushText(push, { restarted, run }) {
  if (run) return `push of #${push.particle} ended while this page was away: ${run.outcome}${run.failure ? ` (${String(run.failure).replace(/^stopped: /, '')})` : ''}, read from its record ${run.record}`;
  return restarted
    ? `push of #${push.particle}: outcome unknown: the server restarted while it ran (a killed server writes no record of it)`
    : `push of #${push.particle}: outcome unknown: the connection closed while it ran and no record of it was found`;
}

/** A haptic link change, for the event log: {text, cls}. `downs`: losses the server counted. */
export function hapticLinkNote(link, downs) {
  const n = Number.isFinite(downs) ? ` (${downs} link loss${downs === 1 ? '' : 'es'} since the server started)` : '';
  return link === 'up'
    ? { text: `haptic link up${n}`, cls: 'good' }
    : { text: `haptic link ${link}: z-control by hand is off until it is back; Engage is disabled${n}`, cls: 'bad' };
}

export class EventLog {
  /**
   * @param {HTMLElement} list the log's `<ol>`
   * @param {HTMLElement} live the polite live region for announcements
   */
  constructor(list, live) {
    this.list = list;
    this.live = live;
  }

  /** Adds a line (`cls`: '', 'good', 'neutral', 'warn' or 'bad'). */
  log(text, cls = '') {
    const li = document.createElement('li');
    const time = document.createElement('time');
    const now = new Date();
    time.dateTime = now.toISOString();
    time.textContent = now.toLocaleTimeString();
    const span = document.createElement('span');
    span.className = cls;
    span.textContent = text;
    li.append(time, span);
    const log = this.list;
    log.prepend(li);
    while (log.children.length > LOG_LINES) log.lastChild.remove();
  }

  /** Says something to screen readers. */
  announce(text) {
    const el = this.live;
    el.textContent = '';
    setTimeout(() => {
      el.textContent = text;
    }, 50);
  }
}
