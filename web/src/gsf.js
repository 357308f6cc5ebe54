// Gwyddion Simple Field records (`/api/records/NAME.gsf`, the scans `nanopush` writes), no DOM:
// the parser the page uses to show a past scan or a late joiner's latest one.

/**
 * Parses a Gwyddion Simple Field (the scan records of `/api/records/NAME.gsf`): the header's
 * `Key = Value` lines, NUL padding to a multiple of 4, then XRes×YRes little-endian f32
 * (row-major, first row = lowest y, as `nanopush` writes it). Throws an Error naming what is wrong.
 * @returns {{xres:number, yres:number, x_real:number, y_real:number, x_offset:number, y_offset:number, title:string, heights:Float32Array}}
 */
export function parseGsf(buf) {
  const bytes = buf instanceof ArrayBuffer ? new Uint8Array(buf) : new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
  const magic = 'Gwyddion Simple Field 1.0\n';
  const head = String.fromCharCode(...bytes.subarray(0, magic.length));
  if (head !== magic) throw new Error('GSF: not a Gwyddion Simple Field (bad first line)');
  const nul = bytes.indexOf(0);
  if (nul < 0) throw new Error('GSF: no NUL after the header');
  const text = new TextDecoder().decode(bytes.subarray(magic.length, nul));
  const kv = {};
  for (const line of text.split('\n')) {
    const i = line.indexOf('=');
    if (i > 0) kv[line.slice(0, i).trim()] = line.slice(i + 1).trim();
  }
  const xres = Number(kv.XRes);
  const yres = Number(kv.YRes);
  if (!Number.isInteger(xres) || !Number.isInteger(yres) || xres < 1 || yres < 1 || xres * yres > 4096 * 4096) {
    throw new Error(`GSF: XRes ${kv.XRes}, YRes ${kv.YRes}: need positive integers`);
  }
  const start = (nul + 4) & ~3;
  const need = start + 4 * xres * yres;
  if (bytes.byteLength !== need) throw new Error(`GSF: ${bytes.byteLength} bytes, ${xres}×${yres} needs ${need}`);
  const v = new DataView(bytes.buffer, bytes.byteOffset + start, 4 * xres * yres);
  const heights = new Float32Array(xres * yres);
  for (let i = 0; i < heights.length; i++) heights[i] = v.getFloat32(4 * i, true);
  const num = (k, d) => (kv[k] !== undefined && Number.isFinite(Number(kv[k])) ? Number(kv[k]) : d);
  return {
    xres, yres, heights,
    x_real: num('XReal', 1), y_real: num('YReal', 1), x_offset: num('XOffset', 0), y_offset: num('YOffset', 0),
    title: kv.Title ?? '',
  };
}
