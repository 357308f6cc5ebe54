// Viridis (perceptually uniform, colour-blind safe): sRGB anchors at 0, 1/8, …, 1, linearly
// interpolated. Pure; the 3D view converts to its linear working space once, into a table.

const VIRIDIS = [
  [68, 1, 84], [72, 40, 120], [62, 73, 137], [49, 104, 142], [38, 130, 142],
  [31, 158, 137], [53, 183, 121], [110, 206, 88], [253, 231, 37],
];

/** sRGB colour (components in [0, 1]) of viridis at u in [0, 1] (clamped; NaN → 0). */
export function viridis(u) {
  if (!(u > 0)) u = 0;
  if (u > 1) u = 1;
  const f = u * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(f));
  const t = f - i;
  const a = VIRIDIS[i];
  const b = VIRIDIS[i + 1];
  return [0, 1, 2].map((k) => (a[k] + (b[k] - a[k]) * t) / 255);
}

/** A table of n viridis colours (sRGB, Float32Array of 3n). */
export function viridisTable(n = 256) {
  const out = new Float32Array(3 * n);
  for (let i = 0; i < n; i++) out.set(viridis(i / (n - 1)), 3 * i);
  return out;
}

/** CSS linear-gradient stops of viridis, for a legend. */
export function viridisCss() {
  return VIRIDIS.map((c, i) => `rgb(${c.join(',')}) ${(100 * i) / (VIRIDIS.length - 1)}%`).join(', ');
}
