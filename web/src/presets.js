// The pattern presets the Assemble panel drops on the map: a line, a grid and a ring, with the
// same parameters, ranges and site order as the instrument's generators
// (instrument/src/assembly/pattern.rs: `line:n=5,spacing_um=4`, `grid:rows=3,cols=3,spacing_um=4`,
// `ring:n=8,radius_um=6`, each with `angle_deg`), centred at a stage point. No DOM; a parameter
// out of range is a RangeError naming it, its value and the allowed range. Runs in Node (tests).
import { ASSEMBLE_MAX_SITES } from './wire.js';

/** The most sites a pattern may have (pattern.rs `MAX_SITES`, as an `assemble` command). */
export const MAX_SITES = ASSEMBLE_MAX_SITES;

/** Each parameter: its words for people, its unit, and its range as pattern.rs checks it. */
export const PARAMS = Object.freeze({
  n: { label: 'sites', whole: true },
  rows: { label: 'rows', whole: true, lo: 1, hi: MAX_SITES },
  cols: { label: 'columns', whole: true, lo: 1, hi: MAX_SITES },
  spacing_um: { label: 'spacing', unit: 'µm', length: true },
  radius_um: { label: 'radius', unit: 'µm', length: true },
  angle_deg: { label: 'angle', unit: '°', lo: -360, hi: 360 },
});

/** The presets: their parameters (in the form's order), defaults, and the least site count. */
export const PRESETS = Object.freeze({
  line: { params: ['n', 'spacing_um', 'angle_deg'], defaults: { n: 5, spacing_um: 4, angle_deg: 0 }, minN: 2 },
  grid: { params: ['rows', 'cols', 'spacing_um', 'angle_deg'], defaults: { rows: 3, cols: 3, spacing_um: 4, angle_deg: 0 } },
  ring: { params: ['n', 'radius_um', 'angle_deg'], defaults: { n: 6, radius_um: 8, angle_deg: 0 }, minN: 3 },
});

const out = (kind, key, v, allowed) => new RangeError(`${kind} ${PARAMS[key].label}: ${v} is out of range; allowed: ${allowed}`);

/** One parameter of a preset, checked: a number within its range (a whole one for counts). */
function param(kind, key, v) {
  const p = PARAMS[key];
  if (v === undefined || v === null || v === '') throw new RangeError(`${kind} needs its ${p.label}`);
  if (typeof v !== 'number' || !Number.isFinite(v)) throw new RangeError(`${kind} ${p.label}: ${v} is not a number`);
  if (p.whole) {
    const lo = key === 'n' ? PRESETS[kind].minN : p.lo;
    const hi = key === 'n' ? MAX_SITES : p.hi;
    if (!Number.isInteger(v) || v < lo || v > hi) throw out(kind, key, v, `a whole number in [${lo}, ${hi}]`);
  } else if (p.length) {
    if (!(v > 0 && v <= 1000)) throw out(kind, key, v, '(0, 1000] µm');
  } else if (!(v >= p.lo && v <= p.hi)) {
    throw out(kind, key, v, `[${p.lo}, ${p.hi}]${p.unit}`);
  }
  return v;
}

/**
 * The sites of preset `kind` with parameters `params` (µm, degrees; `angle_deg` 0 when left
 * out) centred at `atUm` [x, y]: [[x_um, y_um]…] in pattern.rs's order (a grid row by row from
 * its top). Throws a RangeError naming what is wrong and the allowed range.
 */
export function presetSites(kind, params, atUm) {
  const preset = Object.hasOwn(PRESETS, kind) ? PRESETS[kind] : null;
  if (!preset) throw new RangeError(`no preset ${JSON.stringify(kind)}; allowed: ${Object.keys(PRESETS).join(', ')}`);
  const v = {};
  for (const key of preset.params) v[key] = param(kind, key, key === 'angle_deg' ? params[key] ?? 0 : params[key]);
  let local;
  if (kind === 'line') {
    local = Array.from({ length: v.n }, (_, k) => [(k - (v.n - 1) / 2) * v.spacing_um, 0]);
  } else if (kind === 'grid') {
    const count = v.rows * v.cols;
    if (count < 2 || count > MAX_SITES) throw new RangeError(`grid rows × columns: ${count} sites is out of range; allowed: [2, ${MAX_SITES}] sites`);
    local = [];
    for (let r = 0; r < v.rows; r++) {
      for (let c = 0; c < v.cols; c++) local.push([(c - (v.cols - 1) / 2) * v.spacing_um, ((v.rows - 1) / 2 - r) * v.spacing_um]);
    }
  } else {
    local = Array.from({ length: v.n }, (_, k) => {
      const a = (2 * Math.PI * k) / v.n;
      return [v.radius_um * Math.cos(a), v.radius_um * Math.sin(a)];
    });
  }
  const a = (v.angle_deg * Math.PI) / 180;
  const [s, c] = [Math.sin(a), Math.cos(a)];
  return local.map(([x, y]) => [atUm[0] + x * c - y * s, atUm[1] + x * s + y * c]);
}

/** The preset as the command line writes it (the pattern's name): `ring:n=6,radius_um=8`. */
export function presetSpec(kind, params) {
  const keys = PRESETS[kind].params.filter((k) => k !== 'angle_deg' || (params.angle_deg ?? 0) !== 0);
  return `${kind}:${keys.map((k) => `${k}=${params[k]}`).join(',')}`;
}
