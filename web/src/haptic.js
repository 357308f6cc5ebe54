// The haptic panel, shown once telemetry carries a `haptic` object (the server runs a haptic
// link: `--haptic sim|external`): link up/down, the z-control phase (engaged or not), the
// handle's position and the force at the hand, the tip force, the passivity controller, the
// scales in force (lowered, and why, when the device cannot render those asked), a scrolling
// plot of the force at the hand, and the device's fault counters (the line `deviceFaultsLine` of
// src/devicefaults.js makes, from /api/status every 2 s while the panel is shown and the page is
// visible). The lease holder gets engage / release / re-centre and the scales; the commands are
// built (and range-checked) by wire.js. The plot is redrawn by the page's frame scheduler
// (src/frame.js), at most ~7 times a second. `hapticFields` and `HapticTrace` are pure (Node
// tests).
import uPlot from 'uplot';
import { StatusPoller, deviceFaultsLine } from './devicefaults.js';
import { hapticPhaseWords } from './words.js';

const SECONDS = 10;
/** Least time between two redraws of the plot (ms). */
export const HAPTIC_PERIOD_MS = 150;
/** How often the device's fault counters are fetched from /api/status while the panel shows (ms). */
export const DEVICE_FAULTS_PERIOD_MS = 2000;

/**
 * What the panel's fields say for one telemetry frame's `haptic` object: {text, cls} per field
 * (`cls` only where the field is coloured).
 */
export function hapticFields(h) {
  return {
    link: { text: h.link, cls: h.link === 'up' ? 'good' : 'bad' },
    phase: { text: hapticPhaseWords(h.phase) },
    engaged: { text: h.phase === 'engaged' || h.phase === 'pushing' ? 'yes' : 'no' },
    handle: { text: h.handle_m == null ? '–' : `${(h.handle_m * 1e3).toFixed(2)} mm` },
    hand: { text: h.force_n == null ? '–' : `${h.force_n.toFixed(3)} N` },
    tip: { text: `${(h.tip_force_n * 1e9).toFixed(2)} nN` },
    pc: { text: h.pc_active ? 'damping' : 'idle' },
    scales: scalesField(h.scales),
  };
}

/** The haptic scales in force (`/api/status`'s `haptic_scales`), in words; "–" when unknown. */
export function scalesText(sc) {
  if (!sc || !Number.isFinite(sc.nm_per_mm) || !Number.isFinite(sc.pull_off_at_hand_n)) return '–';
  return `${Number(sc.nm_per_mm.toPrecision(4))} nm per mm · pull-off felt as ${Number(sc.pull_off_at_hand_n.toPrecision(4))} N`;
}

/** Why the scales in force differ from those asked, as the panel says it. */
const LIMITS = {
  renderable_region: "lowered to the device's renderable region",
  energy_bounding: 'halved: the passivity damper stayed at its cap (energy bounding)',
};

/**
 * The scales in force (telemetry's `haptic.scales`): the position scale, the pull-off felt at
 * the hand and the contact's stiffness there; when lowered, from what and why (`warn`).
 */
export function scalesField(s) {
  if (!s) return { text: '–', cls: '' };
  const text = `${s.nm_per_mm} nm/mm, ${s.pull_off_at_hand_n.toFixed(3)} N pull-off, felt ${s.felt_stiffness_n_per_m.toFixed(0)} N/m`;
  const why = LIMITS[s.limit];
  if (!why) return { text, cls: '' };
  return { text: `${text} (asked ${s.asked_pull_off_at_hand_n} N: ${why})`, cls: 'warn' };
}

/** The force at the hand over the last `seconds` of server time (a restart starts it again). */
export class HapticTrace {
  constructor(seconds = SECONDS) {
    this.seconds = seconds;
    this.t = [];
    this.f = [];
  }

  push(t, f) {
    if (this.t.length && t < this.t[this.t.length - 1]) {
      this.t.length = 0;
      this.f.length = 0;
    }
    this.t.push(t);
    this.f.push(f);
    let drop = 0;
    while (drop < this.t.length && this.t[drop] < t - this.seconds) drop++;
    if (drop) {
      this.t.splice(0, drop);
      this.f.splice(0, drop);
    }
  }

  /** uPlot's columns: time relative to the newest sample (s), force (N). */
  data() {
    const n = this.t.length;
    const end = n ? this.t[n - 1] : 0;
    return [Float64Array.from(this.t, (v) => v - end), Float64Array.from(this.f)];
  }
}

export class HapticPanel {
  /**
   * @param {{panel: HTMLElement, plot: HTMLElement, fields: Record<string, HTMLElement>, device?: HTMLElement}} els
   *   `device`: where the device's fault line goes
   * @param {import('./frame.js').FrameScheduler} scheduler the page's animation-frame loop
   * @param {object} [opts]
   * @param {() => Promise<object>} [opts.fetchStatus] GETs /api/status (none: no fault line)
   * @param {Document} [opts.doc] the page's document: no fetches while it is hidden
   * @param {{setTimeout, clearTimeout}} [opts.timers]
   */
  constructor(els, scheduler, { fetchStatus, doc, timers, onLinkChange, onScalesChange } = {}) {
    this.els = els;
    this.onLinkChange = onLinkChange;
    this.onScalesChange = onScalesChange;
    this.scales = null; // the scales in force, as last read (words)
    this.link = null; // the link as last seen in telemetry
    this.downs = null; // link losses the server counted (/api/status)
    this.trace = new HapticTrace(SECONDS);
    this.plot = null;
    this.frame = scheduler.register('haptic', () => this.draw(), { period: HAPTIC_PERIOD_MS });
    this.doc = doc;
    this.poller = fetchStatus && els.device
      ? new StatusPoller({
        fetchStatus,
        periodMs: DEVICE_FAULTS_PERIOD_MS,
        timers,
        onStatus: (s) => {
          this.showDeviceFaults(s?.haptic ?? null);
          this.showDowns(s?.haptic?.link_downs);
          this.showScales(s?.haptic_scales);
        },
        onError: () => this.showDeviceFaults(null),
      })
      : null;
    doc?.addEventListener?.('visibilitychange', () => this.syncPolling());
  }

  /** The device's fault line for `/api/status`'s `haptic` (null: unknown, "–"). */
  showDeviceFaults(h) {
    const el = this.els.device;
    if (!el) return;
    const { text, cls } = deviceFaultsLine(h);
    el.textContent = text;
    el.className = cls;
  }

  /**
   * The scales as asked (`/api/status`'s `haptic_scales`): the form's fields filled while
   * untouched. The scales in force are telemetry's (`haptic.scales`, shown by `update`).
   */
  showScales(sc) {
    if (scalesText(sc) === '–') return;
    for (const [el, v] of [[this.els.nmInput, sc.nm_per_mm], [this.els.poInput, sc.pull_off_at_hand_n]]) {
      if (el && (el.value === '' || el.dataset.fromServer === '1') && this.doc?.activeElement !== el) {
        el.value = String(v);
        el.dataset.fromServer = '1';
      }
    }
  }

  /** The scales in force, from telemetry: a change reported (the field itself is `hapticFields`'). */
  noteScales(s) {
    const { text } = scalesField(s);
    if (text === '–') return;
    if (this.scales !== null && this.scales !== text) this.onScalesChange?.(text);
    this.scales = text;
  }

  /** The link losses the server counted since it started. */
  showDowns(n) {
    if (!Number.isFinite(n)) return;
    this.downs = n;
    if (this.els.downs) this.els.downs.textContent = String(n);
  }

  /** Polls /api/status while the panel is shown and the page visible; stops otherwise. */
  syncPolling() {
    if (!this.poller) return;
    if (!this.els.panel.hidden && !this.doc?.hidden) this.poller.start();
    else this.poller.stop();
  }

  /** One telemetry frame's `haptic` (or null: no link on this server). */
  update(t, h) {
    if (!h) return;
    const { panel, fields } = this.els;
    if (panel.hidden) {
      panel.hidden = false;
      this.syncPolling();
    }
    if (this.link !== null && h.link !== this.link) {
      // A loss counted now even before the next status poll confirms it.
      if (h.link !== 'up' && this.downs !== null) this.showDowns(this.downs + 1);
      this.onLinkChange?.(h.link, this.downs ?? undefined);
    }
    this.link = h.link;
    this.noteScales(h.scales);
    for (const [k, v] of Object.entries(hapticFields(h))) {
      if (!fields[k]) continue; // a page without this field
      fields[k].textContent = v.text;
      if (v.cls !== undefined) fields[k].className = v.cls;
    }
    if (t != null && h.force_n != null) {
      this.trace.push(t, h.force_n);
      this.frame.mark();
    }
  }

  /** Draws the plot of the force at the hand (called by the frame scheduler). */
  draw() {
    const el = this.els.plot;
    const [x, y] = this.trace.data();
    if (!this.plot) {
      const axis = { stroke: '#c4ccd6', grid: { stroke: '#3a4554' }, ticks: { stroke: '#3a4554' } };
      this.plot = new uPlot({
        width: Math.max(200, el.clientWidth),
        height: 120,
        legend: { show: true, live: true },
        cursor: { drag: { x: false, y: false } },
        scales: { x: { time: false, range: (u, lo) => [Math.min(lo, -SECONDS), 0] } },
        axes: [{ ...axis, label: 's before now', labelSize: 18, size: 30 }, { ...axis, label: 'N', labelSize: 18, size: 50 }],
        series: [
          { label: 't', value: (u, v) => (v == null ? '–' : `${v.toFixed(2)} s`) },
          { label: 'force at the hand', stroke: '#b48cff', width: 1.5, value: (u, v) => (v == null ? '–' : `${v.toFixed(3)} N`) },
        ],
      }, [x, y], el);
    } else {
      this.plot.setData([x, y]);
    }
  }
}
