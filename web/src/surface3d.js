// The scan in the 3D view: a height-map surface over the scan's region, filled line by line as
// the lines arrive (a `PlaneGeometry` updated in place: `DynamicDrawUsage`, only the rows that
// changed uploaded), unlit viridis colours (by the raw heights, or by the height image's levelled
// heights and colour scale), an outline of the region. Heights in µm, not exaggerated: the view
// scales the group the surface lives in. No DOM: runs in Node (tests).
import * as THREE from 'three';
import { viridisTable } from './colormap.js';

const UM = 1e6; // metres → µm
const LUT_N = 256;
/** Most vertices per side of the 3D surface: a 512² scan is drawn from every 4th pixel (the 2D
 * image keeps every pixel). */
export const MAX_SIDE = 160;

/** Most vertices per side on a software renderer (no GPU): a 512² scan from every 7th pixel. Its
 * 32k triangles at 160 a side cost SwiftShader half of each frame the 3D view is drawn in (45 of
 * 97 ms on a busy 2-core machine); 73² vertices a quarter of that. */
export const MAX_SIDE_SOFTWARE = 80;

/** The 3D surface of an `xres × yres` scan: a vertex at every `step`-th pixel, `nx × ny` of
 * them, at most `maxSide` a side. */
export function surfaceGrid(xres, yres, maxSide = MAX_SIDE) {
  const step = Math.max(1, Math.ceil(Math.max(xres, yres) / maxSide));
  return { step, nx: Math.max(2, Math.ceil(xres / step)), ny: Math.max(2, Math.ceil(yres / step)) };
}

/** Viridis in three.js's linear working colour space, `LUT_N` entries (Float32Array of 3n). */
function linearViridis() {
  const srgb = viridisTable(LUT_N);
  const out = new Float32Array(srgb.length);
  const c = new THREE.Color();
  for (let i = 0; i < LUT_N; i++) {
    c.setRGB(srgb[3 * i], srgb[3 * i + 1], srgb[3 * i + 2], THREE.SRGBColorSpace);
    out[3 * i] = c.r;
    out[3 * i + 1] = c.g;
    out[3 * i + 2] = c.b;
  }
  return out;
}

export class ScanSurface {
  /** @param {THREE.Object3D} parent the group the surface and its outline are added to */
  /**
   * @param {THREE.Object3D} parent
   * @param {{maxSide?: number}} [opts] most vertices a side (MAX_SIDE_SOFTWARE on a software renderer)
   */
  constructor(parent, { maxSide = MAX_SIDE } = {}) {
    this.parent = parent;
    this.maxSide = maxSide;
    this.mesh = null;
    this.outline = null;
    this.scan = null; // the Session's scan state shown (heights in m, row 0 = lowest y)
    // The bounding volumes picking needs, recomputed only when a pick finds them stale.
    this.boundsDirty = false;
    this.lut = linearViridis();
    this.colourRange = null; // {lo, hi} m: the raw heights' colour scale
    this.colourSource = null; // the height image's levelled heights and scale, when coloured by it
    // A whole attribute's upload is pending until the next render: a row's range added now
    // would narrow it.
    this.posFull = false;
    this.colourFull = false;
  }

  /** The next render uploads what is pending; from then on, rows are uploaded one by one. */
  uploaded() {
    this.colourFull = false;
    this.posFull = false;
  }

  /** Whether `scan` is the one shown. */
  shows(scan) {
    return !!this.mesh && this.mesh.userData.scanId === scan.id;
  }

  /** The region's larger side (µm), or null before any scan. */
  sideUm() {
    return this.mesh ? Math.max(this.mesh.userData.wUm, this.mesh.userData.hUm) : null;
  }

  /** The scan's region {x0, y0, w, h} (µm), or null before any scan. */
  regionUm() {
    const m = this.mesh;
    if (!m) return null;
    return { x0: m.position.x - m.userData.wUm / 2, y0: m.position.y - m.userData.hUm / 2, w: m.userData.wUm, h: m.userData.hUm };
  }

  /**
   * Where the substrate goes (µm, not exaggerated) so that it never shows through the scan's
   * low parts: below the lowest height `minM` (m) and zero.
   */
  floorUm(minM) {
    return Math.min(0, minM * UM) - 0.002 * Math.max(this.mesh.userData.wUm, 1e-3);
  }

  /** A new scan: an empty surface over its region, filled as lines arrive. */
  start(scan) {
    this.clear();
    this.scan = scan;
    const { xres, yres } = scan;
    const wUm = scan.x_real * UM;
    const hUm = scan.y_real * UM;
    // Vertices at the centres of every `step`-th pixel (nx × ny of them).
    const { step, nx, ny } = surfaceGrid(xres, yres, this.maxSide);
    const spanX = wUm * ((nx - 1) * step) / xres;
    const spanY = hUm * ((ny - 1) * step) / yres;
    const geom = new THREE.PlaneGeometry(spanX, spanY, nx - 1, ny - 1);
    const pos = geom.getAttribute('position');
    pos.setUsage(THREE.DynamicDrawUsage);
    const col = new THREE.BufferAttribute(new Float32Array(nx * ny * 3), 3);
    col.setUsage(THREE.DynamicDrawUsage);
    geom.setAttribute('color', col);
    geom.setDrawRange(0, 0);
    const mesh = new THREE.Mesh(geom, new THREE.MeshBasicMaterial({ vertexColors: true, side: THREE.DoubleSide }));
    mesh.position.set(scan.x_offset * UM + (wUm / xres) * 0.5 + spanX / 2, scan.y_offset * UM + (hUm / yres) * 0.5 + spanY / 2, 0);
    mesh.userData = { wUm, hUm, xres, yres, nx, ny, step, scanId: scan.id };
    this.mesh = mesh;
    this.parent.add(mesh);
    this.posFull = true;
    this.colourFull = true;
    this.colourRange = null;

    const x0 = scan.x_offset * UM;
    const y0 = scan.y_offset * UM;
    const og = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(
      [x0, y0, 0, x0 + wUm, y0, 0, x0 + wUm, y0 + hUm, 0, x0, y0 + hUm, 0], 3));
    this.outline = new THREE.LineLoop(og, new THREE.LineBasicMaterial({ color: 0x7fe3ff }));
    this.parent.add(this.outline);
  }

  clear() {
    for (const o of [this.mesh, this.outline]) {
      if (o) {
        this.parent.remove(o);
        o.geometry.dispose();
        o.material.dispose();
      }
    }
    this.mesh = null;
    this.outline = null;
  }

  /**
   * Writes line `line` (0 = lowest y) of `scan` (the Session's scan state) into the surface;
   * false when `scan` is not the one shown.
   */
  line(scan, line) {
    const mesh = this.mesh;
    if (!mesh || mesh.userData.scanId !== scan.id) return false;
    const { nx, ny, step } = mesh.userData;
    const geom = mesh.geometry;
    const pos = geom.getAttribute('position');
    const onMesh = line % step === 0 && line / step < ny;
    const row = ny - 1 - line / step; // PlaneGeometry rows run from +y down
    if (onMesh) {
      this.writeRow(scan, line / step);
      // Upload just this row, unless a full upload is pending (a new scan) until the next
      // render: a range added now would narrow it.
      if (!this.posFull) pos.addUpdateRange(row * nx * 3, nx * 3);
      pos.needsUpdate = true;
    }

    // Colour by height: recolour everything when the range grows by more than 2 %.
    const lo = scan.min;
    const hi = scan.max;
    const r = this.colourRange;
    const span = Math.max(hi - lo, 1e-12);
    if (!r || lo < r.lo - 0.02 * span || hi > r.hi + 0.02 * span) {
      this.colourRange = { lo: lo - 0.01 * span, hi: hi + 0.01 * span };
      this.recolour(scan);
    } else if (onMesh) {
      this.colourRow(scan, line / step);
      const col = geom.getAttribute('color');
      // A full upload pending (after a recolour) must not be narrowed to this row.
      if (!this.colourFull) col.addUpdateRange(row * nx * 3, nx * 3);
      col.needsUpdate = true;
    }
    this.updateDrawRange(scan);
    return true;
  }

  /** A whole scan at once (a record opened, or fetched by a late joiner). */
  fill(scan) {
    if (!this.shows(scan)) this.start(scan);
    const { ny } = this.mesh.userData;
    for (let b = 0; b < ny; b++) this.writeRow(scan, b);
    const pos = this.mesh.geometry.getAttribute('position');
    pos.clearUpdateRanges();
    pos.needsUpdate = true;
    this.posFull = true;
    const span = Math.max(scan.max - scan.min, 1e-12);
    this.colourRange = { lo: scan.min - 0.01 * span, hi: scan.max + 0.01 * span };
    this.recolour(scan);
    this.updateDrawRange(scan);
  }

  /** Writes mesh row `b` (scan line b·step) into the positions. */
  writeRow(scan, b) {
    const { xres } = scan;
    const { nx, ny, step } = this.mesh.userData;
    const arr = this.mesh.geometry.getAttribute('position').array;
    const row = ny - 1 - b;
    const line = b * step;
    for (let a = 0; a < nx; a++) {
      const h = scan.heights[line * xres + Math.min(xres - 1, a * step)];
      arr[3 * (row * nx + a) + 2] = Number.isFinite(h) ? h * UM : 0;
    }
  }

  /** Draws the quads between contiguous received mesh rows from the bottom. */
  updateDrawRange(scan) {
    const { nx, ny, step } = this.mesh.userData;
    let k = 0;
    while (k < scan.yres && scan.received[k]) k++;
    // Mesh rows b with b·step < k are in.
    const rows = Math.min(ny, Math.ceil(k / step));
    const quadRows = Math.max(0, rows - 1);
    const total = (ny - 1) * (nx - 1) * 6;
    this.mesh.geometry.setDrawRange(total - quadRows * (nx - 1) * 6, quadRows * (nx - 1) * 6);
    this.boundsDirty = true;
  }

  /**
   * Colours by the height image's levelled heights and its colour scale (`values` indexed as the
   * scan's heights, `lo`, `hi` in m), so one colour means one height in both views; null: by
   * the raw heights (the shape is always the raw heights). True when the colours changed.
   */
  setColourSource(src) {
    this.colourSource = src;
    const scan = this.scan;
    if (this.mesh && scan && (!src || src.values.length === scan.xres * scan.yres)) {
      this.recolour(scan);
      return true;
    }
    return false;
  }

  /** Colours mesh row `b` (scan line b·step). */
  colourRow(scan, b) {
    const { xres } = scan;
    const { nx, ny, step } = this.mesh.userData;
    const col = this.mesh.geometry.getAttribute('color').array;
    const src = this.colourSource && this.colourSource.values.length === xres * scan.yres ? this.colourSource : null;
    const { lo, hi } = src ?? this.colourRange;
    const heights = src ? src.values : scan.heights;
    const inv = (LUT_N - 1) / Math.max(hi - lo, 1e-18);
    const row = ny - 1 - b;
    const line = b * step;
    for (let a = 0; a < nx; a++) {
      const h = heights[line * xres + Math.min(xres - 1, a * step)];
      let k = Math.round((h - lo) * inv);
      k = k > 0 ? (k < LUT_N ? k : LUT_N - 1) : 0;
      const o = 3 * (row * nx + a);
      col[o] = this.lut[3 * k];
      col[o + 1] = this.lut[3 * k + 1];
      col[o + 2] = this.lut[3 * k + 2];
    }
  }

  recolour(scan) {
    const { ny, step } = this.mesh.userData;
    for (let b = 0; b < ny; b++) if (scan.received[b * step]) this.colourRow(scan, b);
    const col = this.mesh.geometry.getAttribute('color');
    col.clearUpdateRanges();
    col.needsUpdate = true;
    this.colourFull = true;
  }

  /** The colour scale now in use (m), for the legend: the height image's when coloured by it. */
  colourScale() {
    const src = this.colourSource;
    const scan = this.scan;
    return src && scan && src.values.length === scan.xres * scan.yres ? { lo: src.lo, hi: src.hi } : this.colourRange;
  }

  /** Height (µm, not exaggerated) of the scan under (x, y) µm, or 0 off the scan. */
  heightUnder(xu, yu) {
    if (!this.mesh || !this.scan) return 0;
    const s = this.scan;
    const fx = (xu - s.x_offset * UM) / (s.x_real * UM);
    const fy = (yu - s.y_offset * UM) / (s.y_real * UM);
    if (fx < 0 || fx >= 1 || fy < 0 || fy >= 1) return 0;
    const i = Math.floor(fx * s.xres);
    const l = Math.floor(fy * s.yres);
    if (!s.received[l]) return 0;
    const h = s.heights[l * s.xres + i];
    return Number.isFinite(h) ? h * UM : 0;
  }

  /** The surface for picking, its bounds brought up to date; null before any scan. */
  pickable() {
    if (!this.mesh) return null;
    if (this.boundsDirty) {
      this.mesh.geometry.computeBoundingSphere();
      this.mesh.geometry.computeBoundingBox();
      this.boundsDirty = false;
    }
    return this.mesh;
  }
}
