// The pattern being drawn in the Assemble panel, no DOM: its sites (stage µm, the map's frame),
// which of them came from one dropped preset (a group, dragged as a whole), the selected site,
// and the pattern's tolerance. Sites stay on the stage [0, range]²; the pattern holds at most
// MAX_SITES; every refusal is a RangeError naming what was wrong and the allowed range. Runs in
// Node (tests).
import { MAX_SITES, presetSites, presetSpec } from './presets.js';

/** A site's tolerance as the server checks it (proto `push::TOLERANCE_RANGE_NM`). */
export const TOLERANCE_RANGE_NM = Object.freeze([1, 100000]);

const um2 = (v) => v.toFixed(2);

export class Pattern {
  /** @param {number} rangeUm the stage's range (µm): sites lie in [0, rangeUm]² */
  constructor(rangeUm = 100) {
    this.rangeUm = rangeUm;
    this.sites = []; // {id, x_um, y_um, group: a preset's id or null}
    this.groups = new Map(); // id → {spec: the preset as the command line writes it, count: its sites}
    this.selected = null; // a site's id
    this.toleranceNm = undefined; // the pattern's tolerance; undefined: the server's default
    this.nextId = 1;
    this.version = 0; // bumped by every change (the map redraws on it)
  }

  changed() {
    this.version++;
  }

  /** A point (µm) checked on the stage; `what` names it in the error. */
  onStage(what, x, y) {
    const r = this.rangeUm;
    if (![x, y].every(Number.isFinite) || x < 0 || x > r || y < 0 || y > r) {
      throw new RangeError(`${what} at (${um2(x)}, ${um2(y)}) µm is off the stage; allowed: x and y in [0, ${r}] µm`);
    }
  }

  room(n) {
    if (this.sites.length + n > MAX_SITES) {
      throw new RangeError(`${this.sites.length + n} sites; allowed: at most ${MAX_SITES} in a pattern`);
    }
  }

  /** The site numbered `id`, or undefined. */
  site(id) {
    return this.sites.find((s) => s.id === id);
  }

  /** The site's number for people: its place in the pattern, from 1. */
  number(id) {
    return this.sites.findIndex((s) => s.id === id) + 1;
  }

  /** Adds a site at (x, y) µm and selects it; returns it. */
  add(xUm, yUm) {
    this.onStage('a site', xUm, yUm);
    this.room(1);
    const s = { id: this.nextId++, x_um: xUm, y_um: yUm, group: null };
    this.sites.push(s);
    this.selected = s.id;
    this.changed();
    return s;
  }

  /**
   * Drops preset `kind` with `params` centred at `atUm`: its sites, one group, the first
   * selected. Nothing is added when any site would be off the stage or the pattern too large.
   */
  drop(kind, params, atUm) {
    this.onStage('the preset\'s centre', atUm[0], atUm[1]);
    const pts = presetSites(kind, params, atUm);
    pts.forEach(([x, y], k) => this.onStage(`${kind} site ${k + 1}`, x, y));
    this.room(pts.length);
    const group = this.nextId++;
    this.groups.set(group, { spec: presetSpec(kind, params), count: pts.length });
    const added = pts.map(([x, y]) => ({ id: this.nextId++, x_um: x, y_um: y, group }));
    this.sites.push(...added);
    this.selected = added[0].id;
    this.changed();
    return added;
  }

  /** The sites that move with site `id`: its preset's, or itself alone. */
  moving(id) {
    const s = this.site(id);
    if (!s) return [];
    return s.group === null ? [s] : this.sites.filter((q) => q.group === s.group);
  }

  /**
   * Moves site `id` (and its preset's sites with it) by (dx, dy) µm, as far as the stage allows:
   * a drag past the edge stops the whole group there. Returns the move made [dx, dy].
   */
  moveBy(id, dxUm, dyUm) {
    const ss = this.moving(id);
    if (!ss.length) return [0, 0];
    const r = this.rangeUm;
    const clamp = (d, vs) => Math.min(r - Math.max(...vs), Math.max(-Math.min(...vs), d));
    const dx = clamp(dxUm, ss.map((s) => s.x_um));
    const dy = clamp(dyUm, ss.map((s) => s.y_um));
    for (const s of ss) {
      s.x_um += dx;
      s.y_um += dy;
    }
    if (dx || dy) this.changed();
    return [dx, dy];
  }

  /** Puts site `id` alone at (x, y) µm (the panel's fields): it leaves its preset's group. */
  place(id, xUm, yUm) {
    const s = this.site(id);
    if (!s) return;
    this.onStage(`site ${this.number(id)}`, xUm, yUm);
    s.x_um = xUm;
    s.y_um = yUm;
    s.group = null;
    this.changed();
  }

  /** Removes site `id`; the next one (else the previous) is selected. */
  remove(id) {
    const i = this.sites.findIndex((s) => s.id === id);
    if (i < 0) return false;
    this.sites.splice(i, 1);
    const g = [...this.groups.keys()].filter((k) => !this.sites.some((s) => s.group === k));
    for (const k of g) this.groups.delete(k);
    this.selected = (this.sites[i] ?? this.sites[i - 1])?.id ?? null;
    this.changed();
    return true;
  }

  clear() {
    this.sites = [];
    this.groups.clear();
    this.selected = null;
    this.changed();
  }

  /** The site whose ring (radius `rUm`) holds (x, y) µm, the nearest; null when none. */
  siteAt(xUm, yUm, rUm) {
    let best = null;
    let bestD = Infinity;
    for (const s of this.sites) {
      const d = Math.hypot(s.x_um - xUm, s.y_um - yUm);
      if (d <= rUm && d < bestD) {
        best = s;
        bestD = d;
      }
    }
    return best;
  }

  /** The tolerance (nm) from the panel's field: undefined when empty (the server's default). */
  setTolerance(nm) {
    if (nm !== undefined && !(Number.isFinite(nm) && nm >= TOLERANCE_RANGE_NM[0] && nm <= TOLERANCE_RANGE_NM[1])) {
      throw new RangeError(`tolerance ${nm} nm is out of range; allowed: [${TOLERANCE_RANGE_NM[0]}, ${TOLERANCE_RANGE_NM[1]}] nm`);
    }
    this.toleranceNm = nm;
    this.changed();
  }

  /**
   * The pattern's name: the preset's spec when it is one whole preset (moved or not), else its
   * site count (`ring:n=6,radius_um=8`, `7 sites`).
   */
  name() {
    const groups = new Set(this.sites.map((s) => s.group));
    const g = groups.size === 1 ? this.groups.get([...groups][0]) : undefined;
    if (g && g.count === this.sites.length) return g.spec;
    return `${this.sites.length} site${this.sites.length === 1 ? '' : 's'}`;
  }
}
