// node --test: GSF records (src/gsf.js) as the server writes them.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseGsf } from '../src/gsf.js';

// A GSF as `write_gsf` (instrument/src/scan) makes it: header, NUL padding to a multiple of 4, f32 LE.

function gsf(header, values) {
  const head = new TextEncoder().encode('Gwyddion Simple Field 1.0\n' + header);
  const pad = 4 - (head.length % 4);
  const out = new Uint8Array(head.length + pad + 4 * values.length);
  out.set(head);
  const v = new DataView(out.buffer, head.length + pad);
  values.forEach((x, i) => v.setFloat32(4 * i, x, true));
  return out.buffer;
}

test('parseGsf reads a record; refuses a wrong size or a foreign file', () => {
  const g = parseGsf(gsf('XRes = 3\nYRes = 2\nXReal = 2e-06\nYReal = 2e-06\nXOffset = 1e-05\nYOffset = 2e-05\nTitle = scan\n', [1, 2, 3, 4, 5, 6]));
  assert.equal(g.xres, 3);
  assert.equal(g.yres, 2);
  assert.equal(g.x_real, 2e-6);
  assert.equal(g.y_offset, 2e-5);
  assert.equal(g.title, 'scan');
  assert.deepEqual([...g.heights], [1, 2, 3, 4, 5, 6]);
  assert.throws(() => parseGsf(gsf('XRes = 3\nYRes = 3\n', [1, 2])), /3×3 needs/);
  assert.throws(() => parseGsf(new TextEncoder().encode('hello').buffer), /not a Gwyddion Simple Field/);
  assert.throws(() => parseGsf(gsf('XRes = x\nYRes = 2\n', [])), /XRes x/);
});
