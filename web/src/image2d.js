// The 2D height image, as an AFM user reads one (Gwyddion's views): the scan in false colour
// with axes in the stage's frame (µm, as the tip readout, the forms and the messages: one frame
// on the whole page, labelled "stage x", "stage y"), a scale bar (a length: nm or µm, chosen for
// the scan's size), a labelled colour bar, plane levelling (mean plane / line by line / none: the maths in src/heightmap.js), a
// cursor readout of x, y and height, and a line profile (drag a line across the image, see the
// height along it in nm; or put its ends at the keyboard cursor of the map layer,
// src/mapoverlay.js, which sits on top and takes the pointer). Without a scan it shows the whole stage, axes and all, so the map layer has
// somewhere to draw the particles and the tip.
// The scan is the Session's scan object (heights in m, row 0 = lowest y); it grows line by line
// and is drawn at most once per animation frame (by the page's frame scheduler, src/frame.js),
// only when something changed.
import { viridisTable } from './colormap.js';
import { lengthUnit, formatLength } from './format.js';
import { level, profileAlong } from './heightmap.js';

const SVG = 'http://www.w3.org/2000/svg';
const M = { left: 58, right: 86, top: 10, bottom: 42 }; // margins (CSS px) around the image
const LUT = (() => {
  const t = viridisTable(256);
  const out = new Uint8ClampedArray(256 * 3);
  for (let i = 0; i < t.length; i++) out[i] = Math.round(t[i] * 255);
  return out;
})();

/** A "nice" step (1, 2, 5 × 10^k) so that `span / step` is about `n`. */
export function niceStep(span, n = 5) {
  const raw = span / n;
  const p = 10 ** Math.floor(Math.log10(raw));
  const f = raw / p;
  return (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10) * p;
}

/**
 * The ticks of a stage axis over [lo, lo + span] (m): stage coordinates at multiples of a nice
 * step (about `n` of them), each with its label in µm, as many decimals as the step needs:
 * [{m, label}]. A scan from 25 to 75 µm is labelled 30, 40 … 70, not 0 … 50.
 */
export function stageTicks(lo, span, n = 5) {
  const stepUm = niceStep(span * 1e6, n);
  const decimals = Math.max(0, Math.ceil(-Math.log10(stepUm) - 1e-9));
  const loUm = lo * 1e6;
  const hiUm = (lo + span) * 1e6;
  const out = [];
  // Indices of the step, not a running sum: no drift over many steps.
  for (let k = Math.ceil(loUm / stepUm - 1e-9); k * stepUm <= hiUm + 1e-9 * stepUm; k++) {
    const um = k * stepUm;
    out.push({ m: um * 1e-6, label: (Math.abs(um) < stepUm / 2 ? 0 : um).toFixed(decimals) });
  }
  return out;
}

/** The cursor readout at stage point (x, y) m, over a height in m (NaN: none): one frame, µm. */
export function readoutText(x, y, h) {
  return `stage x ${(x * 1e6).toFixed(3)} µm, y ${(y * 1e6).toFixed(3)} µm, height ${Number.isFinite(h) ? `${(h * 1e9).toFixed(2)} nm` : '–'}`;
}

/** The readout with the cursor off the image. */
export const NO_READOUT = 'stage x –, y –, height –';

function el(name, attrs = {}, parent = null) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (parent) parent.append(e);
  return e;
}

export class Image2D {
  /**
   * @param {HTMLElement} container
   * @param {{cursorEl?: HTMLElement, profileEl?: HTMLElement, profileInfoEl?: HTMLElement, period?: number}} opts
   *   `period`: at most one draw per slot of this many ms (0: every frame)
   * @param {import('./frame.js').FrameScheduler} scheduler the page's animation-frame loop
   */
  constructor(container, opts, scheduler) {
    this.container = container;
    this.opts = opts ?? {};
    this.scan = null;
    this.mode = 'plane';
    // In the page's live slots (src/frame.js, liveSlotMs): a scan's lines and a profile's drag
    // change the image in the same frames as the map and the plots.
    this.frame = scheduler.register('image2d', () => this.draw(), { period: this.opts.period ?? 0, aligned: true });
    this.drawnVersion = -1;
    this.levelled = null;
    this.range = null;
    this.profile = null;
    this.line = null; // {i0, j0, i1, j1} in pixel coordinates (i along x, j along y, j = 0 lowest)
    this.stage = { x_offset: 0, y_offset: 0, x_real: 100e-6, y_real: 100e-6 }; // shown without a scan
    this.drag = null;

    container.classList.add('img2d');
    this.canvas = document.createElement('canvas');
    this.canvas.setAttribute('aria-hidden', 'true');
    this.svg = el('svg', { class: 'img2d-svg', role: 'img', 'aria-label': 'Height image: no scan yet' });
    container.append(this.canvas, this.svg);
    this.off = document.createElement('canvas');
    this.empty = el('text', { class: 'empty', x: 20, y: 40 }, this.svg);
    this.empty.textContent = 'No scan yet: the whole stage';
    new ResizeObserver(() => this.invalidate()).observe(container);
  }

  /** Something shown changed: redraw in the next animation frame. */
  invalidate() {
    this.frame.mark();
  }

  /** A new scan (the Session's scan object, or null). */
  setScan(scan) {
    this.scan = scan;
    this.line = null;
    this.profile = null;
    this.drawnVersion = -1;
    this.invalidate();
    this.updateProfile();
  }

  /** The stage's range (m): the extent shown while there is no scan. */
  setStage(rangeM) {
    this.stage = { x_offset: 0, y_offset: 0, x_real: rangeM, y_real: rangeM };
    this.invalidate();
  }

  /** What the image spans (m): the scan's area, else the whole stage. */
  extent() {
    return this.scan ?? this.stage;
  }

  setLevelling(mode) {
    this.mode = mode;
    this.drawnVersion = -1;
    this.invalidate();
    this.updateProfile();
  }

  /** The image area (CSS px, relative to the container) and the physical unit. */
  geometry() {
    const sc = this.extent();
    const W = this.container.clientWidth;
    const H = this.container.clientHeight;
    if (W <= 0 || H <= 0) return null;
    const availW = Math.max(10, W - M.left - M.right);
    const availH = Math.max(10, H - M.top - M.bottom);
    // Physically square pixels: the image keeps x_real : y_real.
    const k = Math.min(availW / sc.x_real, availH / sc.y_real);
    const w = sc.x_real * k;
    const h = sc.y_real * k;
    return { x: M.left, y: M.top, w, h, W, H, unit: lengthUnit(Math.max(sc.x_real, sc.y_real)) };
  }

  relevel() {
    const sc = this.scan;
    this.levelled = level(sc, this.mode);
    let lo = Infinity;
    let hi = -Infinity;
    for (const v of this.levelled) {
      if (Number.isFinite(v)) {
        if (v < lo) lo = v;
        if (v > hi) hi = v;
      }
    }
    this.range = lo <= hi ? { lo, hi: hi > lo ? hi : lo + 1e-12 } : null;
    this.opts.onLevelled?.(this.levelled, this.range);
  }

  draw() {
    const sc = this.scan;
    const dpr = Math.min(2, window.devicePixelRatio || 1);
    const W = this.container.clientWidth;
    const H = this.container.clientHeight;
    this.canvas.width = Math.max(1, Math.round(W * dpr));
    this.canvas.height = Math.max(1, Math.round(H * dpr));
    this.canvas.style.width = `${W}px`;
    this.canvas.style.height = `${H}px`;
    this.svg.setAttribute('width', W);
    this.svg.setAttribute('height', H);
    this.svg.setAttribute('viewBox', `0 0 ${W} ${H}`);
    const ctx = this.canvas.getContext('2d');
    ctx.clearRect(0, 0, this.canvas.width, this.canvas.height);
    while (this.svg.lastChild) this.svg.lastChild.remove();
    const g = this.geometry();
    if (!g) return;
    if (!sc) {
      this.drawAxes(g);
      this.empty.setAttribute('x', g.x + 12);
      this.empty.setAttribute('y', g.y + 24);
      this.svg.append(this.empty);
      this.svg.setAttribute('aria-label', 'Height image: no scan yet; the map shows the whole stage');
      this.opts.onDrawn?.();
      return;
    }
    if (this.drawnVersion !== sc.version || !this.levelled) {
      this.relevel();
      this.paintPixels();
      this.drawnVersion = sc.version;
    }
    ctx.imageSmoothingEnabled = false;
    ctx.fillStyle = '#0f141a';
    ctx.fillRect(g.x * dpr, g.y * dpr, g.w * dpr, g.h * dpr);
    ctx.drawImage(this.off, g.x * dpr, g.y * dpr, g.w * dpr, g.h * dpr);
    this.drawAxes(g);
    this.drawScaleBar(g);
    this.drawColourBar(g);
    this.drawProfileLine(g);
    this.opts.onDrawn?.();
    const u = g.unit;
    this.svg.setAttribute('aria-label', `Height image of scan ${sc.id}: ${(sc.x_real * u.scale).toPrecision(3)} × ${(sc.y_real * u.scale).toPrecision(3)} ${u.name}, ${sc.xres} × ${sc.yres} pixels, ${sc.lines} of ${sc.yres} lines`);
  }

  paintPixels() {
    const sc = this.scan;
    const { xres, yres } = sc;
    this.off.width = xres;
    this.off.height = yres;
    const octx = this.off.getContext('2d');
    const img = octx.createImageData(xres, yres);
    const d = img.data;
    const r = this.range;
    const inv = r ? 255 / (r.hi - r.lo) : 0;
    for (let j = 0; j < yres; j++) {
      const row = yres - 1 - j; // canvas rows run from the top (highest y)
      for (let i = 0; i < xres; i++) {
        const v = this.levelled[j * xres + i];
        const o = 4 * (row * xres + i);
        if (!Number.isFinite(v) || !r) {
          d[o + 3] = 0;
          continue;
        }
        let k = Math.round((v - r.lo) * inv);
        k = k < 0 ? 0 : k > 255 ? 255 : k;
        d[o] = LUT[3 * k];
        d[o + 1] = LUT[3 * k + 1];
        d[o + 2] = LUT[3 * k + 2];
        d[o + 3] = 255;
      }
    }
    octx.putImageData(img, 0, 0);
  }

  drawAxes(g) {
    const sc = this.extent();
    const axes = el('g', { class: 'axes' }, this.svg);
    el('rect', { x: g.x, y: g.y, width: g.w, height: g.h, class: 'frame' }, axes);
    for (const t of stageTicks(sc.x_offset, sc.x_real)) {
      const x = g.x + ((t.m - sc.x_offset) / sc.x_real) * g.w;
      el('line', { x1: x, x2: x, y1: g.y + g.h, y2: g.y + g.h + 5, class: 'tick' }, axes);
      el('text', { x, y: g.y + g.h + 17, class: 'xtick', 'text-anchor': 'middle', 'data-value-m': t.m }, axes).textContent = t.label;
    }
    for (const t of stageTicks(sc.y_offset, sc.y_real)) {
      const y = g.y + g.h - ((t.m - sc.y_offset) / sc.y_real) * g.h;
      el('line', { x1: g.x - 5, x2: g.x, y1: y, y2: y, class: 'tick' }, axes);
      el('text', { x: g.x - 8, y: y + 4, class: 'ytick', 'text-anchor': 'end', 'data-value-m': t.m }, axes).textContent = t.label;
    }
    const xl = el('text', { x: g.x + g.w / 2, y: g.y + g.h + 34, class: 'axis-label', 'text-anchor': 'middle' }, axes);
    xl.textContent = 'stage x (µm)';
    const yl = el('text', { x: 14, y: g.y + g.h / 2, class: 'axis-label', 'text-anchor': 'middle', transform: `rotate(-90 14 ${g.y + g.h / 2})` }, axes);
    yl.textContent = 'stage y (µm)';
  }

  drawScaleBar(g) {
    const sc = this.scan;
    const u = g.unit;
    // About a fifth of the width, a round length.
    const len = niceStep(sc.x_real * u.scale, 5) / u.scale;
    const px = (len / sc.x_real) * g.w;
    const x = g.x + 10;
    const y = g.y + g.h - 12;
    const bar = el('g', { class: 'scalebar', 'data-length-m': len }, this.svg);
    el('rect', { x: x - 4, y: y - 18, width: px + 8, height: 26, class: 'scalebar-bg' }, bar);
    el('rect', { x, y, width: px, height: 4, class: 'scalebar-bar' }, bar);
    const t = el('text', { x: x + px / 2, y: y - 5, 'text-anchor': 'middle' }, bar);
    t.textContent = formatLength(len, { digits: 6, ref: Math.max(sc.x_real, sc.y_real) });
  }

  drawColourBar(g) {
    const r = this.range;
    if (!r) return;
    const x = g.x + g.w + 14;
    const w = 14;
    const cb = el('g', { class: 'colourbar' }, this.svg);
    const id = `cbgrad-${Math.random().toString(36).slice(2, 8)}`;
    const defs = el('defs', {}, cb);
    const grad = el('linearGradient', { id, x1: 0, y1: 1, x2: 0, y2: 0 }, defs);
    for (let k = 0; k <= 8; k++) {
      const i = Math.round((k / 8) * 255);
      el('stop', { offset: k / 8, 'stop-color': `rgb(${LUT[3 * i]},${LUT[3 * i + 1]},${LUT[3 * i + 2]})` }, grad);
    }
    el('rect', { x, y: g.y, width: w, height: g.h, class: 'frame', style: `--cb: url(#${id})` }, cb);
    const span = (r.hi - r.lo) * 1e9;
    const step = niceStep(span, 4);
    const first = Math.ceil((r.lo * 1e9) / step) * step;
    for (let v = first; v <= r.hi * 1e9 + 1e-9; v += step) {
      const y = g.y + g.h - ((v - r.lo * 1e9) / span) * g.h;
      el('line', { x1: x + w, x2: x + w + 4, y1: y, y2: y, class: 'tick' }, cb);
      const t = el('text', { x: x + w + 6, y: y + 4, class: 'ctick' }, cb);
      t.textContent = `${Number(v.toPrecision(4))}`;
    }
    const tl = el('text', { x: x + w + 48, y: g.y + g.h / 2, class: 'axis-label', 'text-anchor': 'middle', transform: `rotate(90 ${x + w + 48} ${g.y + g.h / 2})` }, cb);
    // The levelled heights (the 3D view is coloured by them too).
    tl.textContent = this.mode === 'none' ? 'raw height (nm)' : 'levelled height (nm)';
  }

  drawProfileLine(g) {
    const l = this.line;
    if (!l) return;
    const sc = this.scan;
    const px = (i) => g.x + ((i + 0.5) / sc.xres) * g.w;
    const py = (j) => g.y + g.h - ((j + 0.5) / sc.yres) * g.h;
    el('line', { x1: px(l.i0), y1: py(l.j0), x2: px(l.i1), y2: py(l.j1), class: 'profile-line' }, this.svg);
  }

  /** Pixel coordinates (i, j; j = 0 lowest y) of a client point, or null off the image. */
  pixelAt(clientX, clientY, clamp = false) {
    const sc = this.scan;
    const g = this.geometry();
    if (!sc || !g) return null;
    const rect = this.container.getBoundingClientRect();
    let fx = (clientX - rect.left - g.x) / g.w;
    let fy = (g.y + g.h - (clientY - rect.top)) / g.h;
    if (clamp) {
      fx = Math.min(1, Math.max(0, fx));
      fy = Math.min(1, Math.max(0, fy));
    } else if (fx < 0 || fx > 1 || fy < 0 || fy > 1) {
      return null;
    }
    return { i: fx * sc.xres - 0.5, j: fy * sc.yres - 0.5, fx, fy };
  }

  // The pointer, handed on by the map layer on top (src/mapoverlay.js): a drag draws the line
  // profile, the cursor's position is read out.
  pointerDown(e) {
    const p = this.pixelAt(e.clientX, e.clientY);
    if (!p) return;
    this.drag = p;
    e.currentTarget?.setPointerCapture?.(e.pointerId);
    e.preventDefault();
  }

  pointerMove(e) {
    if (this.drag && this.scan) {
      const p = this.pixelAt(e.clientX, e.clientY, true);
      this.line = { i0: this.drag.i, j0: this.drag.j, i1: p.i, j1: p.j };
      this.invalidate();
    }
    this.readout(e.clientX, e.clientY);
  }

  /** The press ended; `click`: it was a click (no drag), which leaves the profile as it was. */
  pointerUp(e, click) {
    const drag = this.drag;
    this.drag = null;
    if (!drag || !this.scan) return;
    if (!click) {
      const p = this.pixelAt(e.clientX, e.clientY, true);
      if (Math.hypot(p.i - drag.i, p.j - drag.j) >= 1) this.line = { i0: drag.i, j0: drag.j, i1: p.i, j1: p.j };
    }
    this.invalidate();
    this.updateProfile();
  }

  pointerLeave() {
    if (this.opts.cursorEl) this.opts.cursorEl.textContent = NO_READOUT;
  }

  /** The line profile's start or end at stage point (x, y) m (the keyboard's way to draw it). */
  profileEnd(which, x, y) {
    const sc = this.scan;
    if (!sc) return;
    const i = ((x - sc.x_offset) / sc.x_real) * sc.xres - 0.5;
    const j = ((y - sc.y_offset) / sc.y_real) * sc.yres - 0.5;
    const l = this.line ?? { i0: i, j0: j, i1: i, j1: j };
    this.line = which === 'start' ? { ...l, i0: i, j0: j } : { ...l, i1: i, j1: j };
    this.invalidate();
    if (Math.hypot(this.line.i1 - this.line.i0, this.line.j1 - this.line.j0) >= 1) this.updateProfile();
  }

  readout(clientX, clientY) {
    const g = this.geometry();
    if (!g) return;
    const rect = this.container.getBoundingClientRect();
    const fx = (clientX - rect.left - g.x) / g.w;
    const fy = (g.y + g.h - (clientY - rect.top)) / g.h;
    if (fx < 0 || fx > 1 || fy < 0 || fy > 1) {
      this.pointerLeave();
      return;
    }
    const e = this.extent();
    this.readoutAt(e.x_offset + fx * e.x_real, e.y_offset + fy * e.y_real);
  }

  /** The readout for stage point (x, y) m: where it is on the stage, and the height there. */
  readoutAt(sx, sy) {
    const out = this.opts.cursorEl;
    if (!out) return;
    let v = NaN;
    const sc = this.scan;
    if (sc && this.levelled) {
      const i = Math.min(sc.xres - 1, Math.max(0, Math.round(((sx - sc.x_offset) / sc.x_real) * sc.xres - 0.5)));
      const j = Math.min(sc.yres - 1, Math.max(0, Math.round(((sy - sc.y_offset) / sc.y_real) * sc.yres - 0.5)));
      v = this.levelled[j * sc.xres + i];
    }
    out.textContent = readoutText(sx, sy, v);
  }

  /** Recomputes the profile along the drawn line and shows it. */
  async updateProfile() {
    const sc = this.scan;
    const l = this.line;
    const info = this.opts.profileInfoEl;
    if (!sc || !l) {
      this.profile = null;
      if (info) info.textContent = ''; // (the title says to drag a line)
      if (this.plot) this.plot.setData([[], []]);
      return;
    }
    if (!this.levelled || this.drawnVersion !== sc.version) this.relevel();
    const { t, h } = profileAlong(this.levelled, sc.xres, sc.yres, l.i0, l.j0, l.i1, l.j1);
    const dx = ((l.i1 - l.i0) / sc.xres) * sc.x_real;
    const dy = ((l.j1 - l.j0) / sc.yres) * sc.y_real;
    const lengthM = Math.hypot(dx, dy);
    const u = lengthUnit(lengthM);
    const xs = Float64Array.from(t, (f) => f * lengthM * u.scale);
    const hs = Float64Array.from(h, (v) => v * 1e9);
    let lo = Infinity;
    let hi = -Infinity;
    for (const v of hs) {
      if (Number.isFinite(v)) {
        lo = Math.min(lo, v);
        hi = Math.max(hi, v);
      }
    }
    this.profile = { lengthM, unit: u.name, distances: xs, heightsNm: hs };
    if (info) info.textContent = `profile length ${(lengthM * u.scale).toPrecision(4)} ${u.name}, height range ${Number.isFinite(hi - lo) ? (hi - lo).toFixed(2) : '–'} nm, ${xs.length} points`;
    const el2 = this.opts.profileEl;
    if (!el2) return;
    const { default: uPlot } = await import('uplot');
    if (!this.plot || this.plotUnit !== u.name) {
      this.plot?.destroy();
      this.plotUnit = u.name;
      this.plot = new uPlot({
        width: Math.max(200, el2.clientWidth),
        height: 150,
        legend: { show: true, live: true },
        cursor: { drag: { x: false, y: false } },
        scales: { x: { time: false } },
        axes: [
          { stroke: '#c4ccd6', grid: { stroke: '#3a4554' }, ticks: { stroke: '#3a4554' }, label: `distance along the line (${u.name})`, labelSize: 18, size: 30 },
          { stroke: '#c4ccd6', grid: { stroke: '#3a4554' }, ticks: { stroke: '#3a4554' }, label: 'height (nm)', labelSize: 18, size: 60 },
        ],
        series: [
          { label: 'distance', value: (p, v) => (v == null ? '–' : `${v.toFixed(3)} ${u.name}`) },
          { label: 'height', stroke: '#7fe3ff', width: 1.5, value: (p, v) => (v == null ? '–' : `${v.toFixed(2)} nm`) },
        ],
      }, [xs, hs], el2);
      new ResizeObserver(() => this.plot?.setSize({ width: Math.max(200, el2.clientWidth), height: 150 })).observe(el2);
    } else {
      this.plot.setData([xs, hs]);
    }
  }
}
