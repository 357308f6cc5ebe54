// The connection to `nanopush serve`, no DOM: the URLs (the page's token passed on to `/ws` and
// the JSON API), the reconnect backoff, and a Connection that owns the WebSocket: it opens it,
// hands messages on, reconnects with backoff (0.25 s doubling to 2 s) and sends commands with
// an id from the Session. Runs in browsers and in Node (tests, with a fake socket and timers).
import { encodeCommand } from './wire.js';

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
   */
  constructor(session, { url, open, onOpen = noop, onMessage = noop, onClose = noop, onCountdown = noop, onSend = noop, onChange = noop, timers = globalThis, now = Date.now }) {
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
    if (sock && typeof sock.then === 'function') sock.then((s) => this.attach(s));
    else this.attach(sock);
  }

  attach(sock) {
    this.ws = sock;
    sock.binaryType = 'arraybuffer';
    let wasOpen = false;
    sock.onopen = () => {
      wasOpen = true;
      this.attempt = 0;
      this.session.opened();
      this.on.onOpen();
    };
    sock.onmessage = (ev) => this.on.onMessage(ev.data);
    sock.onclose = (ev) => {
      if (this.ws !== sock) return;
      this.ws = null;
      this.on.onClose(ev, { wasOpen });
      this.scheduleReconnect();
    };
    sock.onerror = () => {};
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
