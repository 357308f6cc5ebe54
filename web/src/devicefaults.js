// The haptic device's fault counters in one line, for the haptic panel (src/haptic.js)
// and the monitor's tile (src/monitor.js), both from `/api/status`'s `haptic` object: its
// `rate_hz` (the bridge's device cycle rate) and `device_faults` (counters by kind, and `side`:
// the side at fault of each kind, `device`, `bridge` or `cable`). And `StatusPoller`: fetches
// `/api/status` every few seconds, one fetch at a time, only while started. No DOM and no npm
// packages (the monitor imports it); `deviceFaultsLine` and `StatusPoller` run in Node (tests).
import { apiUrl } from './connection.js';

/** The side at fault of each kind, as the server names them (used when `side` is missing). */
export const FAULT_SIDES = Object.freeze({
  bad_packets: 'device',
  timeouts: 'device',
  seq_gaps: 'device',
  out_of_range: 'device',
  watchdog_trips: 'bridge',
  overruns: 'bridge',
  losses: 'cable',
  reopens: 'cable',
});

/** Each kind in words: [one, many]. The cable's kinds are said as what happened to the device. */
const KIND_WORDS = {
  bad_packets: ['bad packet', 'bad packets'],
  timeouts: ['late answer', 'late answers'],
  seq_gaps: ['sequence gap', 'sequence gaps'],
  out_of_range: ['state out of range', 'states out of range'],
  watchdog_trips: ['watchdog trip', 'watchdog trips'],
  overruns: ['late cycle', 'late cycles'],
  losses: ['lost', 'lost'],
  reopens: ['reopened', 'reopened'],
};

const SIDE_ORDER = ['device', 'bridge', 'cable'];

function kindText(kind, n) {
  const w = KIND_WORDS[kind] ?? [kind.replaceAll('_', ' '), kind.replaceAll('_', ' ')];
  return `${n} ${n === 1 ? w[0] : w[1]}`;
}

/** The device cycle's rate in words: "1 kHz", "2.5 kHz", "500 Hz"; null when unknown. */
export function rateText(hz) {
  if (!Number.isFinite(hz) || hz <= 0) return null;
  if (hz >= 1000) return `${Number((hz / 1000).toFixed(2))} kHz`;
  return `${Math.round(hz)} Hz`;
}

/**
 * The haptic device's faults in one line, from `/api/status`'s `haptic` object: {text, cls}.
 * "1 kHz · faults: device 3 (2 bad packets, 1 late answer) · bridge 0 · cable 1 lost,
 * 1 reopened": each side with its total and each nonzero kind by name (the cable's two kinds
 * both, once either is nonzero); "faults: none" when all are zero; "–" when unknown (no
 * haptic link, or no sample from the bridge yet). `cls` is 'bad' while a lost device has not
 * been reopened (losses > reopens), 'warn' when any counter is nonzero, '' otherwise.
 */
export function deviceFaultsLine(haptic) {
  const f = haptic?.device_faults;
  if (!f || typeof f !== 'object') return { text: '–', cls: '' };
  const sideOf = { ...FAULT_SIDES, ...(f.side ?? {}) };
  const kinds = Object.keys(f).filter((k) => k !== 'side' && Number.isFinite(f[k]));
  const bySide = new Map(SIDE_ORDER.map((s) => [s, []]));
  for (const k of kinds) {
    const s = sideOf[k] ?? 'other';
    if (!bySide.has(s)) bySide.set(s, []);
    bySide.get(s).push(k);
  }
  const any = kinds.some((k) => f[k] > 0);
  let faults;
  if (!any) {
    faults = 'faults: none';
  } else {
    const parts = [];
    for (const [side, ks] of bySide) {
      const total = ks.reduce((a, k) => a + f[k], 0);
      if (side === 'cable') {
        parts.push(total ? `cable ${ks.map((k) => kindText(k, f[k])).join(', ')}` : 'cable 0');
      } else if (ks.length || SIDE_ORDER.includes(side)) {
        const named = ks.filter((k) => f[k] > 0).map((k) => kindText(k, f[k]));
        parts.push(named.length ? `${side} ${total} (${named.join(', ')})` : `${side} ${total}`);
      }
    }
    faults = `faults: ${parts.join(' · ')}`;
  }
  const rate = rateText(haptic.rate_hz);
  const lostNow = (f.losses ?? 0) > (f.reopens ?? 0);
  return { text: rate ? `${rate} · ${faults}` : faults, cls: lostNow ? 'bad' : any ? 'warn' : '' };
}

/** GETs `/api/status` with the page's token passed on (as the monitor does); throws unless 2xx. */
export async function fetchStatus(loc, fetchFn = globalThis.fetch) {
  const r = await fetchFn(apiUrl('/api/status', loc));
  if (!r.ok) throw new Error(`HTTP ${r.status}`);
  return r.json();
}

/**
 * Fetches a document every `periodMs` while started: the next fetch is due `periodMs` after the
 * last one ended, so two never overlap (a start while one is in flight waits for it). `onStatus`
 * gets each document, `onError` each failure (a fetch that throws or rejects, or `onStatus`
 * throwing); neither is called after `stop()`. Nothing here throws.
 */
export class StatusPoller {
  /**
   * @param {object} opts
   * @param {() => Promise<object>} opts.fetchStatus
   * @param {(status: object) => void} opts.onStatus
   * @param {(err: Error) => void} [opts.onError]
   * @param {number} [opts.periodMs]
   * @param {{setTimeout, clearTimeout}} [opts.timers]
   */
  constructor({ fetchStatus: fetchFn, onStatus, onError = () => {}, periodMs = 2000, timers = globalThis }) {
    this.fetchStatus = fetchFn;
    this.onStatus = onStatus;
    this.onError = onError;
    this.periodMs = periodMs;
    this.timers = timers;
    this.running = false;
    this.inflight = false;
    this.timer = null;
    this.fetches = 0; // fetches begun (for tests)
  }

  /** Starts polling (a fetch now, unless one is in flight); nothing if already started. */
  start() {
    if (this.running) return;
    this.running = true;
    if (!this.inflight) this.tick();
  }

  /** Stops polling: no further fetch, and the answer of one in flight is dropped. */
  stop() {
    this.running = false;
    this.timers.clearTimeout(this.timer);
    this.timer = null;
  }

  async tick() {
    this.timer = null;
    if (!this.running || this.inflight) return;
    this.inflight = true;
    this.fetches++;
    try {
      const s = await this.fetchStatus();
      if (this.running) this.onStatus(s);
    } catch (e) {
      if (this.running) {
        try {
          this.onError(e);
        } catch {
          // an error handler that throws must not stop the polling
        }
      }
    } finally {
      this.inflight = false;
    }
    if (this.running && this.timer === null) this.timer = this.timers.setTimeout(() => this.tick(), this.periodMs);
  }
}
