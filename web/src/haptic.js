// The haptic panel, shown once telemetry carries a `haptic` object (the server runs a haptic
// link: `--haptic sim|external`): link up/down, the z-control phase (engaged or not), the
// handle's position and the force at the hand, the tip force, the passivity controller, and a
// scrolling plot of the force at the hand. The lease holder gets engage / release / re-centre
// and the scales; the commands are built (and range-checked) by protocol.js.
import uPlot from 'uplot';

const SECONDS = 10;

export class HapticPanel {
  /**
   * @param {{panel: HTMLElement, plot: HTMLElement, fields: Record<string, HTMLElement>}} els
   */
  constructor(els) {
    this.els = els;
    this.t = [];
    this.f = [];
    this.plot = null;
    this.pending = null;
  }

  /** One telemetry frame's `haptic` (or null: no link on this server). */
  update(t, h) {
    if (!h) return;
    const { panel, fields } = this.els;
    if (panel.hidden) panel.hidden = false;
    fields.link.textContent = h.link;
    fields.link.className = h.link === 'up' ? 'good' : 'bad';
    fields.phase.textContent = h.phase;
    fields.engaged.textContent = h.phase === 'engaged' || h.phase === 'pushing' ? 'yes' : 'no';
    fields.handle.textContent = h.handle_m == null ? '–' : `${(h.handle_m * 1e3).toFixed(2)} mm`;
    fields.hand.textContent = h.force_n == null ? '–' : `${h.force_n.toFixed(3)} N`;
    fields.tip.textContent = `${(h.tip_force_n * 1e9).toFixed(2)} nN`;
    fields.pc.textContent = h.pc_active ? 'damping' : 'idle';
    if (t != null && h.force_n != null) {
      if (this.t.length && t < this.t[this.t.length - 1]) {
        this.t.length = 0;
        this.f.length = 0;
      }
      this.t.push(t);
      this.f.push(h.force_n);
      let drop = 0;
      while (drop < this.t.length && this.t[drop] < t - SECONDS) drop++;
      if (drop) {
        this.t.splice(0, drop);
        this.f.splice(0, drop);
      }
      this.redraw();
    }
  }

  redraw() {
    if (this.pending) return;
    this.pending = setTimeout(() => {
      this.pending = null;
      const el = this.els.plot;
      const n = this.t.length;
      const end = n ? this.t[n - 1] : 0;
      const x = Float64Array.from(this.t, (v) => v - end);
      const y = Float64Array.from(this.f);
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
    }, 150);
  }
}
