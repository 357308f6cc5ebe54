// node --test: the haptic panel's texts from a telemetry frame's `haptic` object and its plot's
// 10 s window (src/haptic.js; uPlot itself is not run).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { hapticFields, HapticTrace, scalesField, scalesText } from '../src/haptic.js';

test('the fields of an engaged handle on a live link', () => {
  const f = hapticFields({ link: 'up', phase: 'engaged', handle_m: 0.01234, force_n: 0.5, tip_force_n: 2.5e-9, pc_active: true });
  assert.deepEqual(f, {
    link: { text: 'up', cls: 'good' },
    phase: { text: 'engaged: the hand moves the tip' },
    engaged: { text: 'yes' },
    handle: { text: '12.34 mm' },
    hand: { text: '0.500 N' },
    tip: { text: '2.50 nN' },
    pc: { text: 'damping' },
    scales: { text: '–', cls: '' },
  });
});

test('the scales in force: as asked, lowered, or halved, and why', () => {
  const s = { nm_per_mm: 10, pull_off_at_hand_n: 1, asked_pull_off_at_hand_n: 1, felt_stiffness_n_per_m: 1452.4, limit: 'none' };
  assert.deepEqual(scalesField(s), { text: '10 nm/mm, 1.000 N pull-off, felt 1452 N/m', cls: '' });
  const region = { ...s, pull_off_at_hand_n: 1.3772, asked_pull_off_at_hand_n: 10, felt_stiffness_n_per_m: 2000, limit: 'renderable_region' };
  assert.deepEqual(scalesField(region), {
    text: "10 nm/mm, 1.377 N pull-off, felt 2000 N/m (asked 10 N: lowered to the device's renderable region)",
    cls: 'warn',
  });
  assert.match(scalesField({ ...s, limit: 'energy_bounding' }).text, /energy bounding/);
  assert.equal(hapticFields({ link: 'up', phase: 'engaged', tip_force_n: 0, scales: region }).scales.cls, 'warn');
});

test('a link down, not engaged, no handle reading', () => {
  const f = hapticFields({ link: 'down', phase: 'idle', handle_m: null, force_n: undefined, tip_force_n: 0, pc_active: false });
  assert.deepEqual([f.link.cls, f.engaged.text, f.handle.text, f.hand.text, f.tip.text, f.pc.text], ['bad', 'no', '–', '–', '0.00 nN', 'idle']);
  assert.equal(hapticFields({ link: 'up', phase: 'pushing', tip_force_n: 0 }).engaged.text, 'yes', 'pushing is engaged');
  assert.equal(hapticFields({ link: 'up', phase: 'approach', tip_force_n: 0 }).engaged.text, 'no');
});

test('the force at the hand\'s last 10 s; a server restart starts it again', () => {
  const tr = new HapticTrace();
  for (let i = 0; i <= 300; i++) tr.push(i / 10, i);
  assert.equal(tr.t[0], 20, 'samples from t = 20 s to 30 s: the last 10 s');
  assert.equal(tr.t.length, 101);
  const [x, y] = tr.data();
  assert.equal(x[0], -10);
  assert.equal(x[x.length - 1], 0);
  assert.equal(y[y.length - 1], 300);
  tr.push(1, 7);
  assert.deepEqual([tr.t, tr.f], [[1], [7]], 'the clock went back (a restart): a new plot');
  const [ex, ey] = new HapticTrace().data();
  assert.deepEqual([ex.length, ey.length], [0, 0]);
});

test('the scales in force in words; unknown is "–"', () => {
  assert.equal(scalesText({ nm_per_mm: 10, pull_off_at_hand_n: 1 }), '10 nm per mm · pull-off felt as 1 N');
  assert.equal(scalesText({ nm_per_mm: 0.333333, pull_off_at_hand_n: 2.5 }), '0.3333 nm per mm · pull-off felt as 2.5 N');
  assert.equal(scalesText(null), '–');
  assert.equal(scalesText({ nm_per_mm: 10 }), '–');
});
