// node --test: the wire format (src/wire.js) against the bytes and messages of proto/README.md.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { decodeScanLine, encodeScanLine, FrameError, commands, encodeCommand, pushTolerance } from '../src/wire.js';

// The frame `ScanLineHeader { scan: 2, line: 5, xres: 3, yres: 8, y: 1.5e-6 }.encode(&[1.0, 2.0,

// 3.0])` of proto/src/ws/scan_line.rs, written out byte by byte.

function handFrame() {
  const bytes = [
    0x4e, 0x50, 0x53, 0x4c, // "NPSL"
    0x01, 0x00, // version 1
    0x00, 0x00, // reserved
    0x02, 0x00, 0x00, 0x00, // scan 2
    0x05, 0x00, 0x00, 0x00, // line 5
    0x03, 0x00, 0x00, 0x00, // xres 3
    0x08, 0x00, 0x00, 0x00, // yres 8
    // 1.5e-6 as f64 LE: 0x3EB92A737110E454
    0x54, 0xe4, 0x10, 0x71, 0x73, 0x2a, 0xb9, 0x3e,
    0x00, 0x00, 0x80, 0x3f, // 1.0f32
    0x00, 0x00, 0x00, 0x40, // 2.0f32
    0x00, 0x00, 0x40, 0x40, // 3.0f32
  ];
  return new Uint8Array(bytes);
}

test('decodes a scan line built by hand, byte by byte', () => {
  const f = decodeScanLine(handFrame().buffer);
  assert.equal(f.scan, 2);
  assert.equal(f.line, 5);
  assert.equal(f.xres, 3);
  assert.equal(f.yres, 8);
  assert.equal(f.y, 1.5e-6);
  assert.deepEqual([...f.heights], [1, 2, 3]);
  assert.ok(f.heights instanceof Float32Array);
});

test('decodes from a typed array that is a view into a larger buffer (Node Buffer)', () => {
  const inner = handFrame();
  const big = new Uint8Array(inner.length + 7);
  big.set(inner, 5);
  const f = decodeScanLine(big.subarray(5, 5 + inner.length));
  assert.equal(f.line, 5);
  assert.deepEqual([...f.heights], [1, 2, 3]);
});

test('the JS encoder makes the same bytes as the Rust encoder', () => {
  const b = new Uint8Array(encodeScanLine({ scan: 2, line: 5, xres: 3, yres: 8, y: 1.5e-6 }, [1, 2, 3]));
  assert.deepEqual([...b], [...handFrame()]);
});

test('rejects short frames, a bad magic, another version and a wrong length', () => {
  const f = handFrame();
  const err = (buf, reason, re) => assert.throws(() => decodeScanLine(buf), (e) => {
    assert.ok(e instanceof FrameError, `FrameError, got ${e}`);
    assert.equal(e.reason, reason);
    assert.match(e.message, re);
    return true;
  });
  err(f.slice(0, 20), 'short', /20 bytes, shorter than the 32-byte header/);
  err(f.slice(0, 0), 'short', /0 bytes/);
  err(f.slice(0, 40), 'short', /40 bytes, xres 3 needs 44/);
  const long = new Uint8Array(48);
  long.set(f);
  err(long, 'short', /48 bytes, xres 3 needs 44/);
  const bad = f.slice();
  bad[0] = 'X'.charCodeAt(0);
  err(bad, 'magic', /bad magic "XPSL"/);
  const v2 = f.slice();
  v2[4] = 2;
  err(v2, 'version', /version 2/);
  assert.throws(() => decodeScanLine('NPSL'), TypeError);
});

test('command builders make the documented JSON and refuse out-of-range values', () => {
  assert.equal(encodeCommand(commands.subscribe(['tip', 'scan'])), '{"type":"subscribe","streams":["tip","scan"]}');
  assert.equal(encodeCommand(commands.takeLease(3)), '{"type":"take_lease","id":3}');
  assert.equal(encodeCommand(commands.releaseLease()), '{"type":"release_lease"}');
  assert.deepEqual(JSON.parse(encodeCommand(commands.pushBy(1, 2.5, 90, 7))),
    { type: 'push', id: 7, particle: 1, distance_um: 2.5, direction_deg: 90 });
  assert.deepEqual(commands.pushTo(2, 30, 40.5), { type: 'push', particle: 2, to_x_um: 30, to_y_um: 40.5 });
  assert.deepEqual(commands.scan({ centreXUm: 50, centreYUm: 45, sizeUm: 10, pixels: 128 }),
    { type: 'scan', centre_x_um: 50, centre_y_um: 45, size_um: 10, pixels: 128 });
  assert.deepEqual(commands.scan(), { type: 'scan' }); // the scene's defaults
  assert.deepEqual(commands.scan({ pixels: 64 }), { type: 'scan', pixels: 64 });
  assert.deepEqual(commands.stop(9), { type: 'stop', id: 9 });
  assert.deepEqual(commands.ping(), { type: 'ping' });
  assert.equal(encodeCommand(commands.ack(1234)), '{"type":"ack","seq":1234}');
  assert.throws(() => commands.ack(0), /seq must be a telemetry frame's seq/);
  assert.throws(() => commands.ack(1.5), /seq must be/);

  assert.throws(() => commands.subscribe(['tip', 'video']), /unknown stream "video"/);
  assert.throws(() => commands.pushBy(1, 0, 0), /distance_um must be in \(0, 100\]/);
  assert.throws(() => commands.pushBy(1, 101, 0), /distance_um/);
  assert.throws(() => commands.pushBy(1, 5, 361), /direction_deg must be in \[-360, 360\]/);
  assert.throws(() => commands.pushBy(1, NaN, 0), /distance_um must be a finite number/);
  assert.throws(() => commands.pushBy(1.5, 1, 0), /particle/);
  assert.throws(() => commands.pushTo(1, -1, 5), /to_x_um must be in \[0, 100\]/);
  assert.throws(() => commands.pushTo(1, 5, 60, undefined, 50), /to_y_um must be in \[0, 50\]/);
  assert.throws(() => commands.scan({ pixels: 7 }), /pixels must be an integer in \[8, 512\]/);
  assert.throws(() => commands.scan({ pixels: 64.5 }), /pixels/);
  assert.throws(() => commands.scan({ sizeUm: 0 }), /size_um/);
  assert.throws(() => commands.stop(-1), /id must be a u32/);
  assert.throws(() => encodeCommand({}), TypeError);
});

test('haptic commands: the documented JSON, ranges checked before sending', () => {
  assert.equal(encodeCommand(commands.haptic('engage', {}, 5)), '{"type":"haptic","action":"engage","id":5}');
  assert.equal(encodeCommand(commands.haptic('scale', { nmPerMm: 20 })), '{"type":"haptic","action":"scale","nm_per_mm":20}');
  assert.throws(() => commands.haptic('fly'), /engage, release, recenter or scale/);
  assert.throws(() => commands.haptic('scale'), /nm_per_mm and\/or pull_off_at_hand_n/);
  assert.throws(() => commands.haptic('scale', { nmPerMm: 5000 }), /\[0\.01, 1000\] nm\/mm, got 5000/);
  assert.throws(() => commands.haptic('scale', { pullOffAtHandN: 0 }), /\[0\.01, 10\] N, got 0/);
});

test('a push\'s tolerance: read from the welcome, and checked against it before sending', () => {
  const b = { default: 25, min: 1, max: 100000 };
  assert.deepEqual(pushTolerance({ type: 'welcome', push_tolerance_nm: b }), b);
  for (const bad of [undefined, null, {}, { default: 25, min: 1 }, { default: 0.5, min: 1, max: 10 }, { default: 5, min: 10, max: 1 }, { default: '25', min: 1, max: 100 }]) {
    assert.equal(pushTolerance({ type: 'welcome', push_tolerance_nm: bad }), null, JSON.stringify(bad));
  }
  assert.equal(pushTolerance(undefined), null);
  const push = commands.pushBy(1, 2.5, 90);
  assert.deepEqual(commands.withTolerance(push, 10, b), { ...push, tolerance_nm: 10 });
  assert.equal(commands.withTolerance(push, undefined, b), push, 'left out: the server\'s default');
  assert.throws(() => commands.withTolerance(push, 0.5, b), /tolerance_nm must be in \[1, 100000\] nm, got 0.5/);
  assert.throws(() => commands.withTolerance(push, Infinity), /tolerance_nm must be a finite number/);
  assert.equal(commands.withTolerance(push, 0.5).tolerance_nm, 0.5, 'no range stated: the server checks it');
});

test('assemble: the sites on the stage, the tolerance in its range, plan only or not', () => {
  const sites = [{ x_um: 40, y_um: 41.5 }, { x_um: 44, y_um: 41.5, id: 9 }];
  assert.deepEqual(commands.assemble({ sites, planOnly: true }, 3), { type: 'assemble', sites: [{ x_um: 40, y_um: 41.5 }, { x_um: 44, y_um: 41.5 }], plan_only: true, id: 3 }, 'only the documented fields');
  const m = commands.assemble({ sites, toleranceNm: 50 }, 4, { rangeUm: 100, tolerance: { default: 25, min: 1, max: 100000 } });
  assert.equal(m.tolerance_nm, 50);
  assert.equal(m.plan_only, false);
  assert.throws(() => commands.assemble({ sites: [{ x_um: 101, y_um: 1 }] }), { message: 'site 1: x_um must be in [0, 100] µm, got 101' });
  assert.throws(() => commands.assemble({ sites: [{ x_um: 5, y_um: 5 }, { x_um: 1, y_um: Number.NaN }] }, 1, { rangeUm: 50 }), /site 2: y_um must be in \[0, 50\] µm, got NaN/);
  assert.throws(() => commands.assemble({ sites: [] }), { message: 'an assembly needs 1 to 400 sites, got 0' });
  assert.throws(() => commands.assemble({ sites: Array.from({ length: 401 }, () => ({ x_um: 1, y_um: 1 })) }), /got 401/);
  assert.throws(() => commands.assemble({ sites, toleranceNm: 0.5 }, 1, { tolerance: { default: 25, min: 1, max: 100000 } }), /tolerance_nm must be in \[1, 100000\] nm/);
});
