// A scan's heights as numbers, no DOM: levelled as an AFM user levels them (Gwyddion's mean
// plane and "align rows"), and sampled along a line for a profile. The 2D image (src/image2d.js)
// and the monitor's thumbnail (src/monitor.js) use them; they run in Node (tests).

/**
 * Levelled heights (m) of the received lines: `none`; `plane`, the least-squares mean plane
 * z = a + b·i + c·j subtracted; `line`, each line's mean subtracted (Gwyddion's "align rows").
 * Pixels of lines not yet received are NaN.
 */
export function level(scan, mode) {
  const { xres, yres, heights, received } = scan;
  const out = new Float32Array(xres * yres).fill(NaN);
  if (mode === 'line') {
    for (let j = 0; j < yres; j++) {
      if (!received[j]) continue;
      let s = 0;
      let n = 0;
      for (let i = 0; i < xres; i++) {
        const h = heights[j * xres + i];
        if (Number.isFinite(h)) {
          s += h;
          n++;
        }
      }
      const m = n ? s / n : 0;
      for (let i = 0; i < xres; i++) out[j * xres + i] = heights[j * xres + i] - m;
    }
    return out;
  }
  let a = 0;
  let b = 0;
  let c = 0;
  if (mode === 'plane') {
    // Normal equations of z = a + b i + c j over the finite pixels.
    let n = 0; let si = 0; let sj = 0; let sii = 0; let sjj = 0; let sij = 0; let sz = 0; let siz = 0; let sjz = 0;
    for (let j = 0; j < yres; j++) {
      if (!received[j]) continue;
      for (let i = 0; i < xres; i++) {
        const z = heights[j * xres + i];
        if (!Number.isFinite(z)) continue;
        n++; si += i; sj += j; sii += i * i; sjj += j * j; sij += i * j; sz += z; siz += i * z; sjz += j * z;
      }
    }
    if (n >= 3) {
      // Solve the 3×3 system by Cramer's rule (centred sums keep it well conditioned).
      const mi = si / n; const mj = sj / n; const mz = sz / n;
      const cii = sii - n * mi * mi; const cjj = sjj - n * mj * mj; const cij = sij - n * mi * mj;
      const ciz = siz - n * mi * mz; const cjz = sjz - n * mj * mz;
      const det = cii * cjj - cij * cij;
      if (Math.abs(det) > 1e-12) {
        b = (ciz * cjj - cjz * cij) / det;
        c = (cjz * cii - ciz * cij) / det;
      } else if (cii > 0) {
        b = ciz / cii;
      } else if (cjj > 0) {
        c = cjz / cjj;
      }
      a = mz - b * mi - c * mj;
    } else if (n > 0) {
      a = sz / n;
    }
  }
  for (let j = 0; j < yres; j++) {
    if (!received[j]) continue;
    for (let i = 0; i < xres; i++) out[j * xres + i] = heights[j * xres + i] - (a + b * i + c * j);
  }
  return out;
}

/** Heights along the segment from (i0, j0) to (i1, j1) (pixel coordinates), bilinear. */
export function profileAlong(data, xres, yres, i0, j0, i1, j1) {
  const n = Math.max(2, Math.ceil(Math.hypot(i1 - i0, j1 - j0)) + 1);
  const t = new Float64Array(n);
  const h = new Float64Array(n);
  const at = (i, j) => data[Math.min(yres - 1, Math.max(0, j)) * xres + Math.min(xres - 1, Math.max(0, i))];
  for (let k = 0; k < n; k++) {
    const f = k / (n - 1);
    const x = i0 + f * (i1 - i0);
    const y = j0 + f * (j1 - j0);
    const ix = Math.floor(x);
    const iy = Math.floor(y);
    const fx = x - ix;
    const fy = y - iy;
    const v = (1 - fx) * (1 - fy) * at(ix, iy) + fx * (1 - fy) * at(ix + 1, iy) + (1 - fx) * fy * at(ix, iy + 1) + fx * fy * at(ix + 1, iy + 1);
    t[k] = f;
    h[k] = v;
  }
  return { t, h };
}
