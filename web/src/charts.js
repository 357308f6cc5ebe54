// Strip charts (uPlot): the deflection reading (V) and the tip height (µm) over the last
// seconds of telemetry, against time relative to the newest sample.
import uPlot from 'uplot';

function chart(el, label, unit, colour) {
  const opts = {
    width: Math.max(200, el.clientWidth),
    height: 150,
    legend: { show: true, live: true },
    cursor: { drag: { x: false, y: false } },
    scales: { x: { time: false, range: (u, lo, hi) => [Math.min(lo, -10), 0] } },
    axes: [
      { stroke: '#a9b4c2', grid: { stroke: '#2a323d' }, ticks: { stroke: '#2a323d' }, label: 's before now', labelSize: 18, size: 30 },
      { stroke: '#a9b4c2', grid: { stroke: '#2a323d' }, ticks: { stroke: '#2a323d' }, label: unit, labelSize: 18, size: 60 },
    ],
    series: [
      { label: 't', value: (u, v) => (v == null ? '–' : `${v.toFixed(2)} s`) },
      { label, stroke: colour, width: 1.5, value: (u, v) => (v == null ? '–' : `${v.toFixed(unit === 'V' ? 3 : 4)} ${unit}`) },
    ],
  };
  return new uPlot(opts, [[], []], el);
}

export class Charts {
  constructor(voltsEl, zEl) {
    this.volts = chart(voltsEl, 'deflection', 'V', '#f0a83c');
    this.z = chart(zEl, 'tip height', 'µm', '#7fe3ff');
    this.els = [voltsEl, zEl];
    this.pending = null;
    new ResizeObserver(() => {
      this.volts.setSize({ width: Math.max(200, voltsEl.clientWidth), height: 150 });
      this.z.setSize({ width: Math.max(200, zEl.clientWidth), height: 150 });
    }).observe(voltsEl.parentElement);
  }

  /** Redraws from the Session's trace, at most ~10 times a second. */
  update(trace) {
    if (this.pending) return;
    this.pending = setTimeout(() => {
      this.pending = null;
      const n = trace.t.length;
      const tEnd = n ? trace.t[n - 1] : 0;
      const x = new Float64Array(n);
      const z = new Float64Array(n);
      for (let i = 0; i < n; i++) {
        x[i] = trace.t[i] - tEnd;
        z[i] = trace.z[i] * 1e6;
      }
      this.volts.setData([x, Float64Array.from(trace.volts)]);
      this.z.setData([x, z]);
    }, 100);
  }
}
