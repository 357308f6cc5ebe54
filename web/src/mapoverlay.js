// The height image as the live map: an SVG layer over it (src/image2d.js) with the particles
// where the controller believes they are (solid rings labelled with their ids, the selected one
// highlighted) and where the scan found them (dashed rings), the tip, the form's push preview
// (the selected particle's path to where the push would leave it, an arrow and its end ring),
// the planned push path, the live push trail, the push target and a keyboard cursor. A ring is
// at least MIN_RING_PX in radius, wider than the tip's dot: a particle under the tip (a new page,
// before any scan) still shows. During a push the pushed particle's ring moves with the
// controller's live estimate, and a faint ring stays where it started. Picking there: a click
// on a particle selects it, a click elsewhere picks the push target; by keyboard, the arrows
// move the cursor (Shift: ten times further), Enter picks what is under it, `[` / `]` go to the
// previous / next particle, `s` and `e` put the line profile's start and end at the cursor; a
// pick is announced to screen readers. Drawn by the page's frame loop only when something
// changed, at most 10 times a second; the tip and the pushed particle's ring, which move every
// frame, are small elements of their own moved by a CSS transform (no repaint of the SVG layer:
// a software renderer redrew the whole layer each frame, 28 frames/s instead of 60 at
// 1600×1000). On a software renderer they move 20 times a second, in the same frames as the map
// and the plots (the frame loop's aligned periods), so every other frame is free.
// Everything is placed in the stage's frame (m), as the axes are labelled.
// `toPx`, `toStage`, `nearestParticle`, `stepCursor`, `foundParticles`, `ringPx`, `arrowHead`
// and `TrailBuffer` are pure (Node tests).
import { formatPoint } from './format.js';

const SVG = 'http://www.w3.org/2000/svg';

/** A stage point (m) in the image's CSS px, for geometry `g` and extent `e` (m). */
export function toPx(g, e, x, y) {
  return [g.x + ((x - e.x_offset) / e.x_real) * g.w, g.y + g.h - ((y - e.y_offset) / e.y_real) * g.h];
}

/** The stage point (m) under the image's CSS px (px, py). */
export function toStage(g, e, px, py) {
  return [e.x_offset + ((px - g.x) / g.w) * e.x_real, e.y_offset + ((g.y + g.h - py) / g.h) * e.y_real];
}

/**
 * The particle a pick at stage point (x, y) means: the nearest whose ring (its radius, or at
 * least `minM` for tiny ones) contains the point; null when none does.
 */
export function nearestParticle(particles, x, y, minM) {
  let best = null;
  let bestD = Infinity;
  for (const p of particles) {
    const d = Math.hypot(p.x - x, p.y - y);
    if (d <= Math.max(p.radius, minM) && d < bestD) {
      best = p;
      bestD = d;
    }
  }
  return best;
}

/**
 * The keyboard cursor after an arrow key: a step of 1 % of the extent (10 % with Shift), kept
 * inside it. Returns null for a key that is not an arrow.
 */
export function stepCursor(cur, key, shift, e) {
  const f = shift ? 0.1 : 0.01;
  const d = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] }[key];
  if (!d) return null;
  const clamp = (v, lo, span) => Math.min(lo + span, Math.max(lo, v));
  return [clamp(cur[0] + d[0] * f * e.x_real, e.x_offset, e.x_real), clamp(cur[1] + d[1] * f * e.y_real, e.y_offset, e.y_real)];
}

/** The smallest ring drawn (CSS px): wider than the tip's 12 px dot with its border. */
export const MIN_RING_PX = 10;

/** A particle's ring radius (CSS px) at `k` CSS px per m: its radius, at least MIN_RING_PX. */
export function ringPx(radiusM, k) {
  return Math.max(MIN_RING_PX, radiusM * k);
}

/**
 * The points (px) of an arrow head at `to`, pointing away from `from`: `len` long, `half` wide
 * on each side; null when the two points are one.
 */
export function arrowHead(from, to, len = 10, half = 5) {
  const dx = to[0] - from[0];
  const dy = to[1] - from[1];
  const d = Math.hypot(dx, dy);
  if (!(d > 0)) return null;
  const ux = dx / d;
  const uy = dy / d;
  const bx = to[0] - ux * len;
  const by = to[1] - uy * len;
  return [to, [bx - uy * half, by + ux * half], [bx + uy * half, by - ux * half]];
}

/**
 * The particles a scan record's summary says it found ({x, y, radius} m), those whose numbers
 * are numbers: a damaged summary must not draw rings at NaN.
 */
export function foundParticles(ps) {
  if (!Array.isArray(ps)) return [];
  return ps.filter((p) => p && Number.isFinite(p.x) && Number.isFinite(p.y) && Number.isFinite(p.radius) && p.radius >= 0);
}

/** The live push trail: the tip's recent x, y (m), a point kept when it moved at least `minM`. */
export class TrailBuffer {
  constructor(max = 2000) {
    this.max = max;
    this.pts = [];
  }

  clear() {
    this.pts.length = 0;
  }

  /** Adds a point; true when kept. */
  add(x, y, minM) {
    const last = this.pts[this.pts.length - 1];
    if (last && Math.hypot(x - last[0], y - last[1]) < minM) return false;
    this.pts.push([x, y]);
    if (this.pts.length > this.max) this.pts.splice(0, this.pts.length - this.max);
    return true;
  }
}

function el(name, attrs = {}, parent = null) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (parent) parent.append(e);
  return e;
}

const r1 = (v) => Math.round(v * 10) / 10;

/** Sets an attribute only when its value changes: an SVG attribute set, even to the value it had,
 * repaints the layer (a software renderer's frames halved during a push). */
function setA(node, name, value) {
  const v = String(value);
  if (node.getAttribute(name) !== v) node.setAttribute(name, v);
}

export class MapOverlay {
  /**
   * @param {import('./image2d.js').Image2D} image the height image it sits on
   * @param {object} opts
   * @param {() => object} opts.state the Session's state
   * @param {() => number | null} opts.selected the selected particle's id
   * @param {(id: number) => void} opts.onPickParticle
   * @param {(xUm: number, yUm: number) => void} opts.onPickPoint a push target (µm)
   * @param {() => boolean} opts.canTarget whether a target may be picked now (the lease holder)
   * @param {(text: string) => void} [opts.announce] says a pick to screen readers
   * @param {() => number} [opts.livePeriod] ms between moves of the tip (0: every frame)
   * @param {import('./frame.js').FrameScheduler} scheduler
   */
  constructor(image, opts, scheduler) {
    this.image = image;
    this.opts = opts;
    this.scanParticles = []; // where the shown scan found particles (m): {x, y, radius}
    this.trail = new TrailBuffer();
    this.target = null; // [x, y] m
    this.preview = null; // the form's push preview {from, to} m, or null
    this.cursor = null; // the keyboard cursor [x, y] m, null until the map has focus
    // The pattern's editor (src/siteeditor.js) while "Place sites" is on: it takes the map's
    // clicks, drags and keys before the picking and the line profile do. Null: off.
    this.editor = null;
    this.layer = null; // {draw(ctx)}: the assembly's layer, drawn with the map
    this.frame = scheduler.register('map', () => this.draw(), { period: 100, aligned: true });
    this.liveFrame = scheduler.register('map-live', () => this.drawLive(), { period: opts.livePeriod ?? 0, aligned: true });
    const svg = el('svg', { class: 'map-svg', tabindex: 0, role: 'application', 'aria-roledescription': 'map', 'aria-describedby': 'map-help' });
    svg.setAttribute('aria-label', 'Height image map: particles, tip and push path');
    this.svg = svg;
    const defs = el('defs', {}, svg);
    this.clipId = `mapclip-${Math.random().toString(36).slice(2, 8)}`;
    this.clipRect = el('rect', {}, el('clipPath', { id: this.clipId }, defs));
    const g = el('g', { 'clip-path': `url(#${this.clipId})` }, svg);
    // The assembly's sites, plan and paths (src/assemblymap.js), under the particles.
    this.gAssembly = el('g', { class: 'assembly' }, g);
    this.gScan = el('g', { class: 'scan-particles' }, g);
    this.gBelief = el('g', { class: 'belief' }, g);
    this.gLabels = el('g', { class: 'labels' }, g);
    this.previewMark = el('g', { class: 'push-preview' }, g);
    this.previewLine = el('line', {}, this.previewMark);
    this.previewHead = el('polygon', {}, this.previewMark);
    this.previewEnd = el('circle', {}, this.previewMark);
    this.path = el('polyline', { class: 'push-path' }, g);
    this.trailLine = el('polyline', { class: 'push-trail' }, g);
    this.targetMark = el('g', { class: 'target' }, g);
    el('circle', { r: 7 }, this.targetMark);
    el('line', { x1: -11, x2: 11, y1: 0, y2: 0 }, this.targetMark);
    el('line', { x1: 0, x2: 0, y1: -11, y2: 11 }, this.targetMark);
    this.cursorMark = el('g', { class: 'kbd-cursor' }, svg);
    el('rect', { x: -8, y: -8, width: 16, height: 16 }, this.cursorMark);
    const dot = (cls) => {
      const d = document.createElement('div');
      d.className = `map-dot ${cls}`;
      d.setAttribute('aria-hidden', 'true');
      return d;
    };
    // The pushed particle, where the controller's estimate has it now: a ring with its label.
    this.pushed = dot('pushed');
    this.pushedLabel = document.createElement('span');
    this.pushed.append(this.pushedLabel);
    this.pushedSize = -1;
    this.tip = dot('tip');
    image.container.append(svg, this.pushed, this.tip);
    this.bind();
    new ResizeObserver(() => this.frame.mark()).observe(image.container);
  }

  /** Something the map shows changed: redraw it in the next frame. */
  invalidate() {
    this.frame.mark();
  }

  /** The particles the shown scan found (its record's summary), m. */
  setScanParticles(ps) {
    this.scanParticles = foundParticles(ps);
    this.invalidate();
  }

  /** A push started: its trail starts empty. */
  pushStarted() {
    this.trail.clear();
    this.invalidate();
  }

  /** The form's push preview ({from, to} m: src/controls.js `previewLine`), or null. */
  setPreview(p) {
    this.preview = p;
    this.invalidate();
  }

  /** The push target (µm), or null. */
  setTarget(xUm, yUm) {
    this.target = xUm === null || xUm === undefined ? null : [xUm * 1e-6, yUm * 1e-6];
    this.invalidate();
  }

  /** A telemetry frame: the tip moved (the trail grows while a push runs). */
  tipMoved() {
    const st = this.opts.state();
    const g = this.image.geometry();
    if (st.push && st.tip && g) {
      const e = this.image.extent();
      if (this.trail.add(st.tip.stage[0], st.tip.stage[1], e.x_real / g.w)) this.invalidate();
    }
    this.liveFrame.mark();
  }

  /** The pushed particle during a push (the Session's), or null. */
  pushedParticle(st) {
    return st.push ? (st.particles ?? []).find((p) => p.id === st.push.particle) ?? null : null;
  }

  /**
   * The tip and the pushed particle's ring, at the controller's live estimate (where the push
   * started until the estimate comes): moved by a transform, every frame.
   */
  drawLive() {
    const g = this.image.geometry();
    const st = this.opts.state();
    const e = this.image.extent();
    const place = (node, pt) => {
      let show = !!(g && pt);
      if (show) {
        const [x, y] = toPx(g, e, pt[0], pt[1]);
        show = x >= g.x && x <= g.x + g.w && y >= g.y && y <= g.y + g.h;
        if (show) node.style.transform = `translate(${x.toFixed(1)}px, ${y.toFixed(1)}px)`;
      }
      if (node.hidden === show) node.hidden = !show;
    };
    place(this.tip, st.tip ? st.tip.stage : null);
    const p = this.pushedParticle(st);
    if (p && g) {
      const r = Math.round(ringPx(p.radius, g.w / e.x_real));
      if (r !== this.pushedSize) {
        this.pushedSize = r;
        Object.assign(this.pushed.style, { width: `${2 * r}px`, height: `${2 * r}px`, margin: `${-r}px 0 0 ${-r}px` });
      }
      const text = `#${p.id}`;
      if (this.pushedLabel.textContent !== text) this.pushedLabel.textContent = text;
    }
    const at = p ? (Array.isArray(st.tip?.estimate) ? st.tip.estimate : st.push.path?.[0] ?? [p.x, p.y]) : null;
    place(this.pushed, at);
  }

  draw() {
    const g = this.image.geometry();
    const svg = this.svg;
    const W = this.image.container.clientWidth;
    const H = this.image.container.clientHeight;
    setA(svg, 'width', W);
    setA(svg, 'height', H);
    setA(svg, 'viewBox', `0 0 ${W} ${H}`);
    if (!g) return;
    const e = this.image.extent();
    const st = this.opts.state();
    const px = (x, y) => toPx(g, e, x, y);
    const k = g.w / e.x_real; // CSS px per m
    for (const [a, v] of Object.entries({ x: g.x, y: g.y, width: g.w, height: g.h })) setA(this.clipRect, a, r1(v));
    const sel = this.opts.selected();
    const pushedId = st.push ? st.push.particle : null;
    const rings = (group, ps, cls) => {
      while (group.childElementCount > ps.length) group.lastChild.remove();
      while (group.childElementCount < ps.length) el('circle', {}, group);
      ps.forEach((p, i) => {
        const c = group.children[i];
        const [x, y] = px(p.x, p.y);
        setA(c, 'cx', r1(x));
        setA(c, 'cy', r1(y));
        setA(c, 'r', r1(ringPx(p.radius, k)));
        // The pushed particle's ring moves with its estimate (drawLive): here, where it started.
        const state = p.id === undefined ? '' : p.id === pushedId ? ' start' : p.id === sel ? ' selected' : '';
        setA(c, 'class', `${cls}${state}`);
        if (p.id !== undefined) setA(c, 'data-id', p.id);
      });
    };
    const belief = st.particles ?? [];
    rings(this.gScan, this.scanParticles, 'found');
    rings(this.gBelief, belief, 'particle');
    // Each particle's id beside its ring (the pushed one's moves with it).
    const labels = this.gLabels;
    while (labels.childElementCount > belief.length) labels.lastChild.remove();
    while (labels.childElementCount < belief.length) el('text', { class: 'map-label' }, labels);
    belief.forEach((p, i) => {
      const t = labels.children[i];
      const [x, y] = px(p.x, p.y);
      const r = ringPx(p.radius, k);
      setA(t, 'x', r1(x + r * 0.75 + 3));
      setA(t, 'y', r1(y - r * 0.75 - 3));
      setA(t, 'class', `map-label${p.id === sel ? ' selected' : ''}`);
      setA(t, 'visibility', p.id === pushedId ? 'hidden' : 'visible');
      const text = `#${p.id}`;
      if (t.textContent !== text) t.textContent = text;
    });
    const line = (poly, pts) => {
      setA(poly, 'points', pts ? pts.map(([x, y]) => px(x, y).map(r1).join(',')).join(' ') : '');
    };
    line(this.path, st.push?.path ?? null);
    line(this.trailLine, st.push || this.trail.pts.length ? this.trail.pts : null);
    this.drawPreview(st.push ? null : this.preview, px, k);
    this.layer?.draw({ group: this.gAssembly, px, k, frameKey: `${r1(g.x)},${r1(g.y)},${r1(g.w)},${r1(g.h)}|${e.x_offset},${e.y_offset},${e.x_real},${e.y_real}` });
    const place = (node, pt) => {
      const d = pt ? '' : 'none';
      if (node.style.display !== d) node.style.display = d;
      if (pt) {
        const [x, y] = px(pt[0], pt[1]);
        setA(node, 'transform', `translate(${r1(x)} ${r1(y)})`);
      }
    };
    place(this.targetMark, st.push ? null : this.target);
    place(this.cursorMark, this.cursor);
    this.drawLive();
  }

  /** The form's preview: a dashed line from the particle, an arrow head, the ring at its end. */
  drawPreview(pv, px, k) {
    const d = pv ? '' : 'none';
    if (this.previewMark.style.display !== d) this.previewMark.style.display = d;
    if (!pv) return;
    const a = px(...pv.from);
    const b = px(...pv.to);
    for (const [n, v] of [['x1', a[0]], ['y1', a[1]], ['x2', b[0]], ['y2', b[1]]]) setA(this.previewLine, n, r1(v));
    const head = arrowHead(a, b);
    setA(this.previewHead, 'points', head ? head.map((q) => q.map(r1).join(',')).join(' ') : '');
    const p = (this.opts.state().particles ?? []).find((q) => q.id === this.opts.selected());
    setA(this.previewEnd, 'cx', r1(b[0]));
    setA(this.previewEnd, 'cy', r1(b[1]));
    setA(this.previewEnd, 'r', r1(ringPx(p ? p.radius : 0, k)));
  }

  /** The stage point (m) under a client point, or null off the image. */
  stageAt(clientX, clientY) {
    const g = this.image.geometry();
    if (!g) return null;
    const r = this.image.container.getBoundingClientRect();
    const pxX = clientX - r.left;
    const pxY = clientY - r.top;
    if (pxX < g.x || pxX > g.x + g.w || pxY < g.y || pxY > g.y + g.h) return null;
    return toStage(g, this.image.extent(), pxX, pxY);
  }

  /** A pick at stage point (m): a particle under it is selected, else it is the push target. */
  pick(x, y) {
    const g = this.image.geometry();
    const e = this.image.extent();
    const st = this.opts.state();
    const p = nearestParticle(st.particles ?? [], x, y, (MIN_RING_PX * e.x_real) / g.w);
    const say = this.opts.announce ?? (() => {});
    if (p) {
      this.opts.onPickParticle(p.id);
      say(`particle #${p.id} selected, at ${formatPoint([p.x, p.y])}`);
      return { particle: p.id };
    }
    if (!this.opts.canTarget()) return null;
    this.opts.onPickPoint(x * 1e6, y * 1e6);
    say(`push target ${formatPoint([x, y])}`);
    return { target: [x, y] };
  }

  bind() {
    const svg = this.svg;
    // A press and release without a drag is a pick; a drag draws the line profile (Image2D).
    let down = null;
    // With the editor on, a press on a site drags it (not a line profile); a click adds a site.
    const um = (pt) => (pt ? [pt[0] * 1e6, pt[1] * 1e6] : [null, null]);
    let dragging = false;
    svg.addEventListener('pointerdown', (ev) => {
      if (ev.button !== 0) return;
      down = { x: ev.clientX, y: ev.clientY };
      const s = this.editor && this.stageAt(ev.clientX, ev.clientY);
      if (s && this.editor.down(...um(s), this.hitUm())) {
        dragging = true;
        svg.setPointerCapture?.(ev.pointerId);
        this.invalidate();
        return;
      }
      this.image.pointerDown(ev);
    });
    svg.addEventListener('pointermove', (ev) => {
      if (dragging) {
        const s = this.stageAt(ev.clientX, ev.clientY);
        if (s && this.editor?.move(...um(s))) this.invalidate();
        return;
      }
      this.image.pointerMove(ev);
    });
    svg.addEventListener('pointerup', (ev) => {
      const moved = down ? Math.hypot(ev.clientX - down.x, ev.clientY - down.y) : Infinity;
      if (this.editor) {
        const was = dragging;
        dragging = false;
        down = null;
        if (this.editor.up(...um(this.stageAt(ev.clientX, ev.clientY)), moved < 4)) {
          this.invalidate();
          return;
        }
        if (was) return;
      }
      this.image.pointerUp(ev, moved < 4);
      if (moved < 4) {
        const s = this.stageAt(ev.clientX, ev.clientY);
        if (s) this.pick(s[0], s[1]);
      }
      down = null;
    });
    svg.addEventListener('pointercancel', (ev) => {
      down = null;
      if (dragging) this.editor?.up(null, null, false);
      dragging = false;
      this.image.pointerUp(ev, true);
    });
    svg.addEventListener('pointerleave', () => this.image.pointerLeave());
    svg.addEventListener('focus', () => {
      if (!this.cursor) this.cursor = this.startCursor();
      this.cursorMoved();
    });
    svg.addEventListener('blur', () => {
      this.cursor = null;
      this.invalidate();
    });
    svg.addEventListener('keydown', (ev) => this.key(ev));
  }

  /** A site ring's radius on screen, in stage µm (what a press on a site must fall within). */
  hitUm() {
    const g = this.image.geometry();
    const e = this.image.extent();
    return g ? ((this.layer?.ringPx?.() ?? MIN_RING_PX) * e.x_real * 1e6) / g.w : 0;
  }

  /** Where the keyboard cursor starts: the selected particle, else the middle of the image. */
  startCursor() {
    const e = this.image.extent();
    if (!e) return null;
    const st = this.opts.state();
    const p = (st.particles ?? []).find((q) => q.id === this.opts.selected());
    const inside = p && p.x >= e.x_offset && p.x <= e.x_offset + e.x_real && p.y >= e.y_offset && p.y <= e.y_offset + e.y_real;
    return inside ? [p.x, p.y] : [e.x_offset + e.x_real / 2, e.y_offset + e.y_real / 2];
  }

  cursorMoved() {
    if (this.cursor) this.image.readoutAt(this.cursor[0], this.cursor[1]);
    this.invalidate();
  }

  key(ev) {
    const e = this.image.extent();
    if (!e || ev.altKey || ev.ctrlKey || ev.metaKey) return;
    if (!this.cursor) this.cursor = this.startCursor();
    const next = stepCursor(this.cursor, ev.key, ev.shiftKey, e);
    const st = this.opts.state();
    const ps = [...(st.particles ?? [])].sort((a, b) => a.id - b.id);
    if (next) {
      this.cursor = next;
    } else if (this.editor && !ev.shiftKey && this.editor.key(ev.key, [this.cursor[0] * 1e6, this.cursor[1] * 1e6], this.hitUm())) {
      this.invalidate();
    } else if (ev.key === 'Enter' || ev.key === ' ') {
      this.pick(this.cursor[0], this.cursor[1]);
    } else if ((ev.key === ']' || ev.key === '[') && ps.length) {
      const i = ps.findIndex((p) => p.id === this.opts.selected());
      const j = ev.key === ']' ? (i + 1) % ps.length : (i - 1 + ps.length) % ps.length;
      this.opts.onPickParticle(ps[j].id);
      this.opts.announce?.(`particle #${ps[j].id} selected, at ${formatPoint([ps[j].x, ps[j].y])}`);
      // On the particle, or as near as the image goes (a particle outside the scan).
      this.cursor = [Math.min(e.x_offset + e.x_real, Math.max(e.x_offset, ps[j].x)), Math.min(e.y_offset + e.y_real, Math.max(e.y_offset, ps[j].y))];
    } else if (ev.key === 's' || ev.key === 'e') {
      this.image.profileEnd(ev.key === 's' ? 'start' : 'end', this.cursor[0], this.cursor[1]);
    } else {
      return;
    }
    ev.preventDefault();
    this.cursorMoved();
  }
}
