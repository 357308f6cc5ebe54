// Force and height plots (uPlot, one chart object each, data replaced in place): the tip force
// in nN against time, the tip height against time (last seconds of telemetry, time relative to
// the newest sample), and force against height for the current approach or push (the paper's
// Fig 3 / Fig 9 / Fig 15 views). Redrawn by the page's frame scheduler (src/frame.js) at most ~8
// times a second, never per message. The trace exported as CSV. `chartData`, `traceCsv` and
// `csvFileName` are pure (Node tests).
import uPlot from 'uplot';

/** Least time between two redraws of the plots (ms): at most 5 a second (each redraw of the three
 * plots cost a software renderer a fifth of its frames at 8 a second). */
export const CHART_PERIOD_MS = 200;

const AXIS = { stroke: '#c4ccd6', grid: { stroke: '#3a4554' }, ticks: { stroke: '#3a4554' } };

function chart(el, xLabel, label, unit, colour, digits, xFixed = true, setPoint = false) {
  const opts = {
    width: Math.max(200, el.clientWidth),
    height: 140,
    legend: { show: true, live: true },
    cursor: { drag: { x: false, y: false } },
    scales: { x: xFixed ? { time: false, range: (u, lo) => [Math.min(lo, -10), 0] } : { time: false } },
    axes: [
      { ...AXIS, label: xLabel, labelSize: 18, size: 30 },
      { ...AXIS, label: unit, labelSize: 18, size: 60 },
    ],
    series: [
      { label: xFixed ? 't' : 'height', value: (u, v) => (v == null ? '–' : xFixed ? `${v.toFixed(2)} s` : `${v.toFixed(1)} nm`) },
      { label, stroke: colour, width: 1.5, value: (u, v) => (v == null ? '–' : `${v.toFixed(digits)} ${unit}`) },
      ...(setPoint ? [{ label: 'set point', stroke: '#e6e6e6', width: 1, dash: [6, 4], value: (u, v) => (v == null ? '–' : `${v.toFixed(digits)} ${unit}`) }] : []),
    ],
  };
  return new uPlot(opts, setPoint ? [[], [], []] : [[], []], el);
}

/** CSV of a telemetry trace (SI units in the column names). */
export function traceCsv(trace) {
  const rows = ['t_s,z_m,volts,tip_force_n'];
  for (let i = 0; i < trace.t.length; i++) rows.push(`${trace.t[i]},${trace.z[i]},${trace.volts[i]},${trace.force[i] ?? ''}`);
  return rows.join('\n') + '\n';
}

/** The CSV file's name for a download at `date`: `nanopush-trace-2024-05-01T12-00-00-000Z.csv`. */
export function csvFileName(date) {
  return `nanopush-trace-${date.toISOString().replace(/[:.]/g, '-')}.csv`;
}

/** Downloads the trace as CSV (the "Export CSV" button). */
export function downloadCsv(trace) {
  const blob = new Blob([traceCsv(trace)], { type: 'text/csv' });
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = csvFileName(new Date());
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

/**
 * The plots' data (uPlot's column arrays) from the Session's telemetry trace: time relative to
 * the newest sample (s), the force in nN with the set point (nN, NaN for none) alongside, the
 * height in µm; and force against height (nm above its lowest) for the samples since `since`
 * (server time, s), sorted by height as uPlot needs ascending x.
 * @returns {{force: Float64Array[], z: Float64Array[], fd: Float64Array[]}}
 */
export function chartData(trace, since = -Infinity, setPointN = null) {
  const n = trace.t.length;
  const tEnd = n ? trace.t[n - 1] : 0;
  const x = new Float64Array(n);
  const z = new Float64Array(n);
  const f = new Float64Array(n);
  for (let i = 0; i < n; i++) {
    x[i] = trace.t[i] - tEnd;
    z[i] = trace.z[i] * 1e6;
    f[i] = (trace.force[i] ?? NaN) * 1e9;
  }
  const sp = (len) => new Float64Array(len).fill(setPointN === null ? NaN : setPointN * 1e9);
  // Force against height since the push / approach began (or the whole window).
  let i0 = 0;
  while (i0 < n && trace.t[i0] < since) i0++;
  let zmin = Infinity;
  for (let i = i0; i < n; i++) zmin = Math.min(zmin, trace.z[i]);
  const idx = [];
  for (let i = i0; i < n; i++) idx.push(i);
  idx.sort((a, b) => trace.z[a] - trace.z[b]);
  return {
    force: [x, f, sp(n)],
    z: [x, z],
    fd: [Float64Array.from(idx, (i) => (trace.z[i] - zmin) * 1e9), Float64Array.from(idx, (i) => (trace.force[i] ?? NaN) * 1e9), sp(idx.length)],
  };
}

export class Charts {
  /**
   * @param {HTMLElement} forceEl
   * @param {HTMLElement} zEl
   * @param {HTMLElement} fdEl
   * @param {import('./frame.js').FrameScheduler} scheduler the page's animation-frame loop
   */
  constructor(forceEl, zEl, fdEl, scheduler) {
    this.force = chart(forceEl, 's before now', 'tip force', 'nN', '#f0a83c', 2, true, true);
    this.z = chart(zEl, 's before now', 'tip height', 'µm', '#7fe3ff', 4);
    this.fd = chart(fdEl, 'tip height above its lowest (nm)', 'tip force', 'nN', '#ff7ab8', 2, false, true);
    this.setPointN = null; // the strategy's contact set point as a force (N), drawn dashed
    this.since = -Infinity; // the force-distance plot starts here (s, server time)
    this.trace = null; // the Session's trace, drawn in the next frame that may
    this.frame = scheduler.register('charts', () => this.draw(), { period: CHART_PERIOD_MS, aligned: true });
    const els = [forceEl, zEl, fdEl];
    new ResizeObserver(() => {
      for (const [c, e] of [[this.force, els[0]], [this.z, els[1]], [this.fd, els[2]]]) c.setSize({ width: Math.max(200, e.clientWidth), height: 140 });
    }).observe(forceEl.parentElement);
  }

  /** The set point (N) drawn on both force plots; null: none. */
  setSetPoint(n) {
    this.setPointN = Number.isFinite(n) ? n : null;
  }

  /** The force-distance plot restarts here (server time, s): a push or approach begins. */
  restartFd(t) {
    this.since = t;
  }

  /** Redraws from the Session's trace, at most ~8 times a second. */
  update(trace) {
    this.trace = trace;
    this.frame.mark();
  }

  draw() {
    const d = chartData(this.trace, this.since, this.setPointN);
    this.force.setData(d.force);
    this.z.setData(d.z);
    this.fd.setData(d.fd);
  }
}
