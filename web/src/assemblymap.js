// The assembly on the live map, in its stage frame (m): the pattern's sites as rings of the
// particle size they want with their tolerance inside (dashed while drawn or planned, solid and
// filled once a particle holds the site, marked with a cross and its reason when it cannot be
// filled), numbered as the report numbers them; the plan's assignment (a thin line from each
// particle to its site) and its paths (one per move, by purpose), the move running highlighted.
// `patternView` and `assemblyView` say what to draw (pure, Node tests); AssemblyLayer draws it
// in an SVG group the map gives it, only when what it shows or the map's frame changed.
import { siteState } from './assembly.js';
import { siteWords } from './assemblyreport.js';
import { ringPx, MIN_RING_PX } from './mapoverlay.js';

const SVG = 'http://www.w3.org/2000/svg';

/** The least tolerance circle drawn (CSS px): 25 nm is a tenth of a pixel on a 100 µm map. */
export const MIN_TOL_PX = 2;
/** Site numbers are drawn up to this many sites (more would cover the map). */
export const MAX_LABELS = 60;

/** The pattern being drawn: its sites (m) with the pattern's tolerance (m), the selected one. */
export function patternView(pattern, defaultTolNm) {
  const tol = (pattern.toleranceNm ?? defaultTolNm ?? 25) / 1e9;
  return {
    sites: pattern.sites.map((s, i) => ({ x: s.x_um / 1e6, y: s.y_um / 1e6, tol, n: i + 1, state: 'draft', reason: null, selected: s.id === pattern.selected })),
    assign: [],
    paths: [],
    current: null,
  };
}

/** An assembly (the Session's): its sites in their states, the plan's assignment and paths. */
export function assemblyView(a) {
  const map = a.plan?.map ?? [];
  const sites = a.sites.map((s, i) => {
    const { state, reason } = siteState(a, i);
    return { x: s.target[0], y: s.target[1], tol: s.tolerance, n: i + 1, state, reason, selected: false };
  });
  // The plan stays drawn after a plan-only assembly's end: that is what it was asked for.
  const live = !a.done || a.done.outcome === 'planned';
  const assign = [];
  if (live) {
    (a.plan?.sites ?? []).forEach((p, i) => {
      const q = map[p.particle];
      if (p.state === 'planned' && q && a.sites[i]) assign.push([[q.x, q.y], a.sites[i].target]);
    });
  }
  const paths = !live ? [] : (a.plan?.moves ?? []).filter((m) => Array.isArray(m.path) && m.path.length > 1).map((m) => ({ pts: m.path, purpose: m.purpose }));
  return { sites, assign, paths, current: a.current?.path ?? null };
}

/** A site's tooltip: its number, state and reason in words. */
export function siteTitle(s) {
  const what = s.state === 'draft' ? 'in the pattern' : siteWords(s.state);
  return `site ${s.n}: ${what}${s.reason ? ` (${s.reason})` : ''}`;
}

function el(name, attrs, parent) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  parent.append(e);
  return e;
}

const r1 = (v) => Math.round(v * 10) / 10;

export class AssemblyLayer {
  /**
   * @param {SVGGElement} group the map's group it draws in (clipped to the image)
   * @param {() => ({view: object, key: string, radiusM: number} | null)} source what to draw
   *   (patternView / assemblyView), a key that changes whenever it does, and the radius (m) of
   *   the particles the sites want; null: nothing
   */
  constructor(group, source) {
    this.g = group;
    this.source = source;
    this.key = null;
    this.ringR = MIN_RING_PX;
  }

  /** A site ring's radius (CSS px) as last drawn. */
  ringPx() {
    return this.ringR;
  }

  /** Draws, with the map's `px` (stage m → CSS px) and `k` (px per m), when anything changed. */
  draw({ px, k, frameKey }) {
    const src = this.source();
    this.ringR = ringPx(src?.radiusM ?? 0, k);
    const key = src ? `${src.key}|${frameKey}|${r1(this.ringR)}` : null;
    if (key === this.key) return;
    this.key = key;
    this.g.replaceChildren();
    if (src) this.build(src.view, px, k, this.ringR);
  }

  build(view, px, k, ringR) {
    const pts = (list) => list.map(([x, y]) => px(x, y).map(r1).join(',')).join(' ');
    for (const [from, to] of view.assign) {
      const [a, b] = [px(...from), px(...to)];
      el('line', { class: 'asm-assign', x1: r1(a[0]), y1: r1(a[1]), x2: r1(b[0]), y2: r1(b[1]) }, this.g);
    }
    for (const p of view.paths) el('polyline', { class: `asm-path ${p.purpose}`, points: pts(p.pts) }, this.g);
    if (view.current) el('polyline', { class: 'asm-path current', points: pts(view.current) }, this.g);
    const labels = view.sites.length <= MAX_LABELS;
    for (const s of view.sites) {
      const [x, y] = px(s.x, s.y);
      const g = el('g', { class: `asm-site ${s.state}${s.selected ? ' selected' : ''}`, transform: `translate(${r1(x)} ${r1(y)})` }, this.g);
      el('title', {}, g).textContent = siteTitle(s);
      el('circle', { class: 'ring', r: r1(ringR) }, g);
      el('circle', { class: 'tol', r: r1(Math.max(MIN_TOL_PX, s.tol * k)) }, g);
      if (['missed', 'unreachable', 'refused'].includes(s.state)) {
        const d = r1(ringR * 0.7);
        el('path', { class: 'cross', d: `M${-d},${-d}L${d},${d}M${-d},${d}L${d},${-d}` }, g);
      }
      if (labels) el('text', { class: 'asm-label', x: r1(-ringR - 3), y: r1(-ringR - 2) }, g).textContent = String(s.n);
    }
  }
}
