// The haptic panel, shown once telemetry carries a `haptic` object (the server runs a haptic
// link: `--haptic sim|external`): link up/down, the z-control phase (engaged or not), the
// handle's position and the force at the hand, the tip force, the passivity controller, the
// scales in force (lowered, and why, when the device cannot render those asked: issue 25), and a
// scrolling plot of the force at the hand, and the device's fault counters (issue 28: the line
// `deviceFaultsLine` of src/devicefaults.js makes, from /api/status every 2 s while the panel is
// shown and the page is visible). The lease holder gets engage / release / re-centre
// and the scales; the commands are built (and range-checked) by wire.js. The plot is redrawn by
// the page's frame scheduler (src/frame.js), at most ~7 times a second. `hapticFields` and
// `HapticTrace` are pure (Node tests).
import uPlot from 'uplot';
import { StatusPoller, deviceFaultsLine } from './devicefaults.js';

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
    phase: { text: h.phase },
    engaged: { text: h.phase === 'engaged' || h.phase === 'pushing' ? 'yes' : 'no' },
    handle: { text: h.handle_m == null ? '–' : `${(h.handle_m * 1e3).toFixed(2)} mm` },
    hand: { text: h.force_n == null ? '–' : `${h.force_n.toFixed(3)} N` },
    tip: { text: `${(h.tip_force_n * 1e9).toFixed(2)} nN` },
    pc: { text: h.pc_active ? 'damping' : 'idle' },
    scales: scalesField(h.scales),
  };
}

/** Why the scales in force differ from those asked (issue 25), as the panel says it. */
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
  constructor(els, scheduler, { fetchStatus, doc, timers } = {}) {
    this.els = els;
    this.trace = new HapticTrace(SECONDS);
    this.plot = null;
    this.frame = scheduler.register('haptic', () => this.draw(), { period: HAPTIC_PERIOD_MS });
    this.doc = doc;
    this.poller = fetchStatus && els.device
      ? new StatusPoller({
        fetchStatus,
        periodMs: DEVICE_FAULTS_PERIOD_MS,
        timers,
        onStatus: (s) => this.showDeviceFaults(s?.haptic ?? null),
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
