// The status bar at the top of the page: link, the instrument (its backend and rate), role,
// client, lease, phase, lagged messages and the last error, from the Session's state.
// `statusFields` is pure (Node tests); StatusBar writes it into the page.
import { holderText } from './session.js';
import { phaseWords, instrumentText, instrumentTitle } from './words.js';

/**
 * What the status bar says for a Session state. `conn` is null while waiting to reconnect (the
 * countdown says it then); the others are {text, cls?} or text.
 * @param {object} st the Session's state
 * @param {{demo?: boolean}} [opts] `demo`: the page talks to the stand-in socket of `?demo`
 */
export function statusFields(st, { demo = false } = {}) {
  let conn = null;
  if (st.connection === 'open') conn = { kind: 'open', text: demo ? 'demo (no server)' : 'connected' };
  else if (st.connection === 'connecting') conn = { kind: 'connecting', text: 'connecting…' };
  else if (!st.reconnect) conn = { kind: 'closed', text: 'closed' };
  const mine = st.lease !== null && st.lease === st.client;
  const e = st.lastError;
  const unknown = st.connection !== 'open' && (st.instance ?? st.version) !== null && (st.instance ?? st.version) !== undefined;
  const err = {
    text: e ? `${e.code}${e.id !== null ? ` (#${e.id}${e.command ? ` ${e.command}` : ''})` : ''}: ${e.message}` : 'none',
    cls: e ? 'err' : '',
  };
  const lagged = st.lagged.events ? `${st.lagged.events}× (${st.lagged.skipped} msgs)` : '0';
  // The instrument stays named while disconnected, as the last known (a restart may bring another).
  const instrument = {
    text: instrumentText(st.instrument),
    title: `${unknown && st.instrument ? 'Last known, while disconnected. ' : ''}${instrumentTitle(st.instrument)}`,
    cls: unknown ? 'unknown' : '',
  };
  // Disconnected after having been connected: what the server said no longer holds.
  if (unknown) return { conn, instrument, role: 'unknown', client: 'unknown', lease: { text: 'unknown', cls: 'unknown' }, phase: 'unknown', lagged, error: err };
  return {
    conn,
    instrument,
    role: String(st.role ?? '–'),
    client: String(st.client ?? '–'),
    lease: { text: st.lease === null ? 'free' : st.lease === st.client ? `you (${st.name ? `${st.name}, ` : ''}${st.lease})` : holderText(st), cls: mine ? 'mine' : '' },
    phase: phaseWords(st.phase),
    lagged,
    error: err,
  };
}

export class StatusBar {
  /** @param {(id: string) => HTMLElement} $ the page's elements by id */
  constructor($, { demo = false } = {}) {
    this.demo = demo;
    this.el = {
      conn: $('st-conn'), instrument: $('instrument-status'), role: $('st-role'), client: $('st-client'), lease: $('st-lease'),
      phase: $('st-phase'), lagged: $('st-lagged'), error: $('st-error'),
    };
  }

  /** The link's dot colour (`open`, `connecting`, `closed`) and words. */
  setConn(kind, text) {
    const el = this.el.conn;
    el.className = `conn-${kind}`;
    el.querySelector('.txt').textContent = text;
  }

  render(st) {
    const f = statusFields(st, { demo: this.demo });
    const el = this.el;
    if (f.conn) this.setConn(f.conn.kind, f.conn.text);
    el.instrument.textContent = f.instrument.text;
    el.instrument.title = f.instrument.title;
    el.instrument.className = f.instrument.cls;
    el.role.textContent = f.role;
    el.client.textContent = f.client;
    el.lease.textContent = f.lease.text;
    el.lease.className = f.lease.cls;
    el.phase.textContent = f.phase;
    el.phase.className = f.phase === 'unknown' ? 'unknown' : '';
    el.role.className = f.role === 'unknown' ? 'unknown' : '';
    el.lagged.textContent = f.lagged;
    el.error.textContent = f.error.text;
    el.error.title = f.error.text;
    el.error.className = f.error.cls;
  }
}
