// The connection to `nanopush serve`, no DOM: the URLs (the page's token passed on to `/ws` and
// the JSON API), the reconnect backoff, and a Connection that owns the WebSocket: it opens it,
// hands messages on, reconnects with backoff (0.25 s doubling to 2 s) and sends commands with
// an id from the Session. Runs in browsers and in Node (tests, with a fake socket and timers).
import { commands, encodeCommand } from './wire.js';

/**
 * The WebSocket URL for a page location: same host, `/ws`, with the page's `token` query
 * parameter passed on (none → a viewer connection).
 */
export function wsUrl(loc) {
  const proto = loc.protocol === 'https:' ? 'wss:' : 'ws:';
  const token = new URLSearchParams(loc.search || '').get('token');
  return `${proto}//${loc.host}/ws` + (token ? `?token=${encodeURIComponent(token)}` : '');
}

/** An HTTP API path with the page's `?token=` passed on (a server with a viewer token needs it). */
export function apiUrl(path, loc) {
  const token = new URLSearchParams(loc.search || '').get('token');
  if (!token) return path;
  return path + (path.includes('?') ? '&' : '?') + `token=${encodeURIComponent(token)}`;
}

/**
 * Exchanges the page's `?token=` for the server's session cookie (HttpOnly and SameSite=Strict:
 * no script reads it, no other site sends it) and removes the token from the address bar and
 * the history entry (`history.replaceState`), so it stays in no browser history, bookmark,
 * proxy log or `Referer`. Resolves to the server's `{name, role}`, or null: no token in the URL,
 * or the server refused it or has no `/api/session` (the token is then left where it is, and the
 * page's connection carries it and says why it fails).
 * @param {Location} loc the page's location
 * @param {{fetchFn?: typeof fetch, history?: History}} [deps]
 */
export async function exchangeToken(loc, { fetchFn = globalThis.fetch, history = globalThis.history } = {}) {
  const params = new URLSearchParams(loc.search || '');
  const token = params.get('token');
  if (!token) return null;
  let r;
  try {
    r = await fetchFn('/api/session', { method: 'POST', headers: { Authorization: `Bearer ${token}` }, credentials: 'same-origin' });
  } catch {
    return null;
  }
  if (!r.ok) return null;
  params.delete('token');
  const q = params.toString();
  history.replaceState(history.state, '', `${loc.pathname}${q ? `?${q}` : ''}${loc.hash || ''}`);
  try {
    return await r.json();
  } catch {
    return null;
  }
}

/**
 * What to tell a person the server does not know (a server with a token file or a viewer
 * token, and no token in the URL nor a cookie it believes: a first visit without the link, a
 * revoked token, a cookie over a week old), or null: `GET /api/session` answers 401 (429:
 * too many failed attempts from here). Null too when the server cannot be asked (the demo).
 * @param {{fetchFn?: typeof fetch}} [deps]
 */
export async function signInNote({ fetchFn = globalThis.fetch } = {}) {
  let r;
  try {
    r = await fetchFn('/api/session', { credentials: 'same-origin' });
  } catch {
    return null;
  }
  if (r.status === 401) return 'This instrument needs your token: open the address you were given (it ends in ?token=…), or ask for a token (nanopush token add NAME --role operator|viewer).';
  if (r.status === 429) return `The server refuses this address for now: ${await r.text().catch(() => 'too many failed attempts')}`;
  return null;
}

/**
 * Reconnect delay (ms) for the n-th attempt (1-based): 0.25 s doubling to 2 s at most. The
 * server is one instrument on the lab's network, not a crowded service: a page that waits
 * longer than 2 s after it came back (7 s, as it did with a 15 s cap) shows a stale instrument.
 */
export function backoffMs(attempt, baseMs = 250, maxMs = 2000) {
  const n = Math.max(1, attempt);
  return Math.min(maxMs, baseMs * 2 ** (n - 1));
}

/** What the status bar says while waiting to reconnect (`leftMs` until the next attempt). */
export function reconnectText(leftMs, attempt) {
  return `reconnecting in ${(leftMs / 1000).toFixed(1)} s (attempt ${attempt})`;
}

const noop = () => {};

/**
 * Silence (ms) after which a socket is given up and another tried: the server streams telemetry
 * all the time (tens of frames a second), so this long without a frame is a hung server or a
 * network that drops packets without closing; a handshake that takes this long too. The
 * server gives a client the same 5 s to take a frame.
 */
export const SILENCE_MS = 5000;

/**
 * Telemetry acknowledgements go at most this often (ms): ten a second per page instead of sixty,
 * well within the half second of frames the server keeps in flight to a page.
 */
export const ACK_EVERY_MS = 100;

/**
 * The page's WebSocket: one at a time, reopened after it closes (the n-th attempt after
 * `backoffMs(n)`; an open resets the count). The Session hears of every change (`connecting`,
 * `opened`, `closed`) and numbers the commands sent.
 */
export class Connection {
  /**
   * @param {import('./session.js').Session} session
   * @param {object} opts
   * @param {string} opts.url the WebSocket URL
   * @param {(url: string) => WebSocket | Promise<WebSocket>} opts.open makes a socket (may throw)
   * @param {() => void} [opts.onOpen] the socket opened (after `session.opened()`)
   * @param {(data: string | ArrayBuffer) => void} [opts.onMessage] a message arrived
   * @param {(ev: CloseEvent, info: {wasOpen: boolean}) => void} [opts.onClose] the socket closed
   *   (before `session.closed()`); `wasOpen`: it had opened (else: an attempt the server refused)
   * @param {(text: string) => void} [opts.onCountdown] the time left until the next attempt, in words
   * @param {(msg: object) => void} [opts.onSend] a command got its id and is about to go
   * @param {() => void} [opts.onChange] the Session's connection state changed
   * @param {{setTimeout, clearTimeout, setInterval, clearInterval}} [opts.timers]
   * @param {() => number} [opts.now] wall clock (ms)
   * @param {number} [opts.silenceMs] a socket silent this long is given up (0: never)
   */
  constructor(session, { url, open, onOpen = noop, onMessage = noop, onClose = noop, onCountdown = noop, onSend = noop, onChange = noop, timers = globalThis, now = Date.now, silenceMs = SILENCE_MS }) {
    this.session = session;
    this.url = url;
    this.open = open;
    this.on = { onOpen, onMessage, onClose, onCountdown, onSend, onChange };
    this.timers = timers;
    this.now = now;
    this.ws = null;
    this.attempt = 0; // reconnect attempts since the last open
    this.reconnectTimer = null;
    this.countdownTimer = null;
    this.silenceMs = silenceMs;
    this.watchdog = null; // checks the socket's silence once a second
    // Telemetry acknowledged: the newest sent and when, the newest read and not yet sent, and
    // the timer that will send it.
    this.acked = 0;
    this.ackedAt = -Infinity;
    this.ackDue = 0;
    this.ackTimer = null;
  }

  /** Opens a socket (now: the reconnect timer, if any, is cancelled). */
  connect() {
    this.timers.clearTimeout(this.reconnectTimer);
    this.session.connecting();
    this.on.onChange();
    let sock;
    try {
      sock = this.open(this.url);
    } catch (e) {
      this.session.logError('client_socket', e.message);
      this.scheduleReconnect();
      return;
    }
    if (sock && typeof sock.then === 'function') {
      sock.then((s) => this.attach(s), (e) => {
        this.session.logError('client_socket', e?.message ?? String(e));
        this.scheduleReconnect();
      });
    } else this.attach(sock);
  }

  attach(sock) {
    this.ws = sock;
    // Another socket (maybe another run of the server, whose frames count from 1 again).
    this.timers.clearTimeout(this.ackTimer);
    this.ackTimer = null;
    this.acked = 0;
    this.ackDue = 0;
    this.ackedAt = -Infinity;
    sock.binaryType = 'arraybuffer';
    let wasOpen = false;
    let heard = this.now();
    sock.onopen = () => {
      wasOpen = true;
      heard = this.now();
      this.attempt = 0;
      this.session.opened();
      this.on.onOpen();
    };
    sock.onmessage = (ev) => {
      heard = this.now();
      this.on.onMessage(ev.data);
    };
    const gone = (ev) => {
      if (this.ws !== sock) return;
      this.ws = null;
      this.timers.clearInterval(this.watchdog);
      this.on.onClose(ev, { wasOpen });
      this.scheduleReconnect();
    };
    sock.onclose = gone;
    sock.onerror = () => {};
    this.timers.clearInterval(this.watchdog);
    if (this.silenceMs > 0) {
      this.watchdog = this.timers.setInterval(() => {
        if (this.now() - heard <= this.silenceMs) return;
        const reason = `no word from the server for ${this.silenceMs / 1000} s`;
        gone({ code: null, reason });
        try {
          sock.close();
        } catch {
          // (closing a dead socket: nothing to do)
        }
      }, 1000);
    }
  }

  scheduleReconnect() {
    const t = this.timers;
    this.attempt++;
    const delay = backoffMs(this.attempt);
    this.session.closed(this.attempt, delay);
    const due = this.now() + delay;
    t.clearInterval(this.countdownTimer);
    const tick = () => {
      const left = Math.max(0, due - this.now());
      this.on.onCountdown(reconnectText(left, this.attempt));
      if (left <= 0) t.clearInterval(this.countdownTimer);
    };
    this.countdownTimer = t.setInterval(tick, 250);
    this.on.onChange();
    tick();
    this.reconnectTimer = t.setTimeout(() => {
      t.clearInterval(this.countdownTimer);
      this.connect();
    }, delay);
  }

  /**
   * Acknowledges telemetry frame `seq` as read (`ack`: no id, no reply, so not numbered by the
   * Session): at most every ACK_EVERY_MS, the newest read going when the time comes (a trailing
   * ack: the server sends nothing more while what it sent is unacknowledged); nothing when not
   * connected.
   */
  ack(seq) {
    if (this.ws?.readyState !== 1 || seq <= this.acked) return;
    this.ackDue = Math.max(this.ackDue, seq);
    if (this.ackTimer !== null) return;
    const flush = () => {
      this.ackTimer = null;
      const due = this.ackDue;
      if (due <= this.acked || this.ws?.readyState !== 1) return;
      this.ws.send(encodeCommand(commands.ack(due)));
      this.acked = due;
      this.ackedAt = this.now();
    };
    const wait = this.ackedAt + ACK_EVERY_MS - this.now();
    if (wait <= 0) flush();
    else this.ackTimer = this.timers.setTimeout(flush, wait);
  }

  /** Sends a command with the Session's next id; null (and an error logged) when not connected. */
  send(msg) {
    if (!this.ws || this.ws.readyState !== 1) {
      this.session.logError('client_socket', 'not connected: the command was not sent');
      this.on.onChange();
      return null;
    }
    const m = this.session.issue(msg);
    this.on.onSend(m);
    this.ws.send(encodeCommand(m));
    return m;
  }
}
