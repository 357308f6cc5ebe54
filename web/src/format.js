// Numbers in words for the page, no DOM: lengths (the one length formatter), points, the tip
// readout, file sizes and times. Runs in browsers and in Node (tests).

/** The length unit that suits a size (m): nm below 2 µm, else µm. */
export function lengthUnit(sizeM) {
  return Math.abs(sizeM) < 2e-6 ? { name: 'nm', scale: 1e9 } : { name: 'µm', scale: 1e6 };
}

/**
 * A length (m) in nm or µm. Two styles:
 * - by default (labels: the colour legend, particle radii, scan sizes), fixed decimals: nm below
 *   1 µm (one decimal below 10 nm, else none), µm above (two decimals below 10 µm, else one):
 *   `250 nm`, `5.0 nm`, `1.50 µm`, `12.5 µm`;
 * - with `digits`, that many significant digits (trailing zeros dropped) in the unit
 *   `lengthUnit(ref)` picks (nm below 2 µm; `ref` defaults to the length itself), so that the
 *   labels of one axis or scale bar share a unit: `250 nm`, `1500 nm`, `12.5 µm`.
 * @param {number} m
 * @param {{digits?: number, ref?: number}} [opts]
 */
export function formatLength(m, { digits, ref = m } = {}) {
  if (digits !== undefined) {
    const u = lengthUnit(ref);
    return `${Number((m * u.scale).toPrecision(digits))} ${u.name}`;
  }
  const a = Math.abs(m);
  if (a < 1e-6) return `${(m * 1e9).toFixed(a < 1e-8 ? 1 : 0)} nm`;
  return `${(m * 1e6).toFixed(a < 1e-5 ? 2 : 1)} µm`;
}

/**
 * A stage point (m) in µm, as the map's axes, the forms and the tip readout have it (one frame on
 * the whole page): `(50.00, 60.00) µm`; also near the origin, never in nm.
 */
export function formatPoint([x, y]) {
  return `(${(x * 1e6).toFixed(2)}, ${(y * 1e6).toFixed(2)}) µm`;
}

/** A stage position (m) in µm with nm resolution: `(40.000, 31.500) µm`. */
export function formatStagePoint([x, y]) {
  return `(${(x * 1e6).toFixed(3)}, ${(y * 1e6).toFixed(3)}) µm`;
}

/**
 * The tip readout of a telemetry sample (the Session's `tip`): where it is on the stage, its
 * height, the force on it and the deflection signal. The phase is the status bar's, the pushed
 * particle's estimate the push's progress line (src/pushprogress.js): the readout stays one line.
 */
export function formatTip(t) {
  const [, , z] = t.stage;
  return `tip ${formatStagePoint(t.stage)} · z ${(z * 1e9).toFixed(1)} nm · ${((t.force ?? 0) * 1e9).toFixed(2)} nN · ${t.volts.toFixed(3)} V`;
}

/** A file size: `512 B`, `2.0 KiB`, `3.5 MiB`; '' for a non-number. */
export function formatBytes(n) {
  if (typeof n !== 'number') return '';
  if (n < 1024) return `${n} B`;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(1)} KiB`;
  return `${(n / 1024 / 1024).toFixed(1)} MiB`;
}

/** A time (seconds or milliseconds since the epoch, or a date string) in the browser's locale. */
export function formatTime(t) {
  if (t === undefined || t === null) return '';
  const d = typeof t === 'number' ? new Date(t < 1e12 ? t * 1000 : t) : new Date(t);
  return Number.isNaN(d.getTime()) ? String(t) : d.toLocaleString();
}
