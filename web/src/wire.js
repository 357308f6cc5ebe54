// The wire format of the nanopush WebSocket protocol (proto/README.md, proto/src/ws/), no
// DOM: the binary scan-line frames (`NPSL`, decoded and, for tests and the demo, encoded) and
// the client's JSON commands (builders that check the documented ranges, and `encodeCommand`).
// Runs in browsers and in Node (tests).

/** `ws::WS_VERSION`: the protocol version this client speaks. */
export const WS_VERSION = 1;
/** Magic of a scan-line frame. */
export const SCAN_LINE_MAGIC = 'NPSL';
/** Header length of a scan-line frame (bytes). */
export const SCAN_LINE_HEADER_LEN = 32;
/** Streams a client can subscribe to. */
export const STREAMS = Object.freeze(['tip', 'scan']);
/** The most sites an `assemble` command may give (proto `ws::ASSEMBLE_MAX_SITES`). */
export const ASSEMBLE_MAX_SITES = 400;

/** A binary frame that is not a valid scan line. `reason` is `short`, `magic` or `version`. */
export class FrameError extends Error {
  constructor(reason, message) {
    super(message);
    this.name = 'FrameError';
    this.reason = reason;
  }
}

function toDataView(buf) {
  if (buf instanceof ArrayBuffer) return new DataView(buf);
  if (ArrayBuffer.isView(buf)) return new DataView(buf.buffer, buf.byteOffset, buf.byteLength);
  throw new TypeError('decodeScanLine: expected an ArrayBuffer or a typed array');
}

/**
 * Decodes one binary scan-line frame (little-endian): magic `NPSL`, u16 version (1), u16
 * reserved, u32 scan, u32 line, u32 xres, u32 yres, f64 line y (m), then xres f32 heights (m).
 * Throws a FrameError on a short frame, a bad magic, an unknown version or a length that does
 * not match xres, as `ScanLineHeader::decode` does.
 * @returns {{scan:number, line:number, xres:number, yres:number, y:number, heights:Float32Array}}
 */
export function decodeScanLine(buf) {
  const v = toDataView(buf);
  if (v.byteLength < SCAN_LINE_HEADER_LEN) {
    throw new FrameError('short', `scan line: ${v.byteLength} bytes, shorter than the ${SCAN_LINE_HEADER_LEN}-byte header`);
  }
  const magic = String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3));
  if (magic !== SCAN_LINE_MAGIC) {
    throw new FrameError('magic', `scan line: bad magic ${JSON.stringify(magic)} (expected "NPSL")`);
  }
  const version = v.getUint16(4, true);
  if (version !== 1) {
    throw new FrameError('version', `scan line: version ${version}, this client reads version 1`);
  }
  const scan = v.getUint32(8, true);
  const line = v.getUint32(12, true);
  const xres = v.getUint32(16, true);
  const yres = v.getUint32(20, true);
  const y = v.getFloat64(24, true);
  const need = SCAN_LINE_HEADER_LEN + 4 * xres;
  if (v.byteLength !== need) {
    throw new FrameError('short', `scan line: ${v.byteLength} bytes, xres ${xres} needs ${need}`);
  }
  const heights = new Float32Array(xres);
  for (let i = 0; i < xres; i++) heights[i] = v.getFloat32(SCAN_LINE_HEADER_LEN + 4 * i, true);
  return { scan, line, xres, yres, y, heights };
}

/** Encodes a scan line as the Rust encoder does (for tests and demos). */
export function encodeScanLine({ scan, line, xres, yres, y }, heights) {
  const b = new ArrayBuffer(SCAN_LINE_HEADER_LEN + 4 * heights.length);
  const v = new DataView(b);
  for (let i = 0; i < 4; i++) v.setUint8(i, SCAN_LINE_MAGIC.charCodeAt(i));
  v.setUint16(4, 1, true);
  v.setUint16(6, 0, true);
  v.setUint32(8, scan, true);
  v.setUint32(12, line, true);
  v.setUint32(16, xres, true);
  v.setUint32(20, yres, true);
  v.setFloat64(24, y, true);
  heights.forEach((h, i) => v.setFloat32(SCAN_LINE_HEADER_LEN + 4 * i, h, true));
  return b;
}

// ---------------------------------------------------------------------------------------------
// Client → server messages. Each builder returns a plain object with only the documented
// fields (the server refuses unknown ones) and checks the documented ranges first, throwing a
// RangeError that names the field, so the operator hears about a typo before a round trip.

function finite(name, x) {
  if (typeof x !== 'number' || !Number.isFinite(x)) throw new RangeError(`${name} must be a finite number, got ${x}`);
  return x;
}

function withId(msg, id) {
  if (id !== undefined && id !== null) {
    if (!Number.isInteger(id) || id < 0 || id > 0xffffffff) throw new RangeError(`id must be a u32, got ${id}`);
    msg.id = id;
  }
  return msg;
}

function particleId(p) {
  if (!Number.isInteger(p) || p < 0 || p > 0xffffffff) throw new RangeError(`particle must be a particle id (u32), got ${p}`);
  return p;
}

export const commands = {
  subscribe(streams = STREAMS, id) {
    for (const s of streams) if (!STREAMS.includes(s)) throw new RangeError(`streams: unknown stream ${JSON.stringify(s)} (tip, scan)`);
    return withId({ type: 'subscribe', streams: [...streams] }, id);
  },
  takeLease(id) {
    return withId({ type: 'take_lease' }, id);
  },
  releaseLease(id) {
    return withId({ type: 'release_lease' }, id);
  },
  /** Push `particle` by `distanceUm` (0, 100] along `directionDeg` [-360, 360] (from +x). */
  pushBy(particle, distanceUm, directionDeg, id) {
    finite('distance_um', distanceUm);
    finite('direction_deg', directionDeg);
    if (!(distanceUm > 0 && distanceUm <= 100)) throw new RangeError(`distance_um must be in (0, 100] µm, got ${distanceUm}`);
    if (!(directionDeg >= -360 && directionDeg <= 360)) throw new RangeError(`direction_deg must be in [-360, 360], got ${directionDeg}`);
    return withId({ type: 'push', particle: particleId(particle), distance_um: distanceUm, direction_deg: directionDeg }, id);
  },
  /** Push `particle` to the target (µm) in [0, rangeUm]². */
  pushTo(particle, xUm, yUm, id, rangeUm = 100) {
    finite('to_x_um', xUm);
    finite('to_y_um', yUm);
    if (!(xUm >= 0 && xUm <= rangeUm)) throw new RangeError(`to_x_um must be in [0, ${rangeUm}] µm, got ${xUm}`);
    if (!(yUm >= 0 && yUm <= rangeUm)) throw new RangeError(`to_y_um must be in [0, ${rangeUm}] µm, got ${yUm}`);
    return withId({ type: 'push', particle: particleId(particle), to_x_um: xUm, to_y_um: yUm }, id);
  },
  /**
   * A push command `m` (from pushBy or pushTo) judged with `toleranceNm` (nm): `ok` only when
   * the scan after it finds the particle that close to the target. Left out (undefined), the
   * server's default. `bounds` is the range the server checks, as its `welcome` states it
   * (pushTolerance); without them the server alone checks the range.
   */
  withTolerance(m, toleranceNm, bounds) {
    if (toleranceNm === undefined || toleranceNm === null) return m;
    finite('tolerance_nm', toleranceNm);
    if (bounds && !(toleranceNm >= bounds.min && toleranceNm <= bounds.max)) {
      throw new RangeError(`tolerance_nm must be in [${bounds.min}, ${bounds.max}] nm, got ${toleranceNm}`);
    }
    return { ...m, tolerance_nm: toleranceNm };
  },
  /** A scan; any of centreXUm, centreYUm, sizeUm (0, 100], pixels [8, 512] may be left out. */
  scan({ centreXUm, centreYUm, sizeUm, pixels } = {}, id) {
    const m = { type: 'scan' };
    if (centreXUm !== undefined && centreXUm !== null) m.centre_x_um = finite('centre_x_um', centreXUm);
    if (centreYUm !== undefined && centreYUm !== null) m.centre_y_um = finite('centre_y_um', centreYUm);
    if (sizeUm !== undefined && sizeUm !== null) {
      finite('size_um', sizeUm);
      if (!(sizeUm > 0 && sizeUm <= 100)) throw new RangeError(`size_um must be in (0, 100] µm, got ${sizeUm}`);
      m.size_um = sizeUm;
    }
    if (pixels !== undefined && pixels !== null) {
      if (!Number.isInteger(pixels) || pixels < 8 || pixels > 512) throw new RangeError(`pixels must be an integer in [8, 512], got ${pixels}`);
      m.pixels = pixels;
    }
    return withId(m, id);
  },
  stop(id) {
    return withId({ type: 'stop' }, id);
  },
  /**
   * Assembles particles into `sites` ({x_um, y_um}, 1 to 400, on the stage [0, rangeUm]²), each
   * judged with `toleranceNm` (left out: the server's default; checked against `tolerance`, the
   * range the server's `welcome` states, when given). `planOnly`: the server plans and says so,
   * and nothing moves.
   */
  assemble({ sites, toleranceNm, planOnly = false }, id, { rangeUm = 100, tolerance = null } = {}) {
    if (!Array.isArray(sites) || sites.length < 1 || sites.length > ASSEMBLE_MAX_SITES) {
      throw new RangeError(`an assembly needs 1 to ${ASSEMBLE_MAX_SITES} sites, got ${Array.isArray(sites) ? sites.length : 'none'}`);
    }
    const out = sites.map((site, k) => {
      for (const key of ['x_um', 'y_um']) {
        const v = site[key];
        if (!(typeof v === 'number' && v >= 0 && v <= rangeUm)) throw new RangeError(`site ${k + 1}: ${key} must be in [0, ${rangeUm}] µm, got ${v}`);
      }
      return { x_um: site.x_um, y_um: site.y_um };
    });
    const m = commands.withTolerance({ type: 'assemble', sites: out, plan_only: !!planOnly }, toleranceNm, tolerance);
    return withId(m, id);
  },
  /**
   * A haptic z-control command: `engage`, `release`, `recenter`, or `scale` with `nmPerMm`
   * [0.01, 1000] and/or `pullOffAtHandN` [0.01, 10].
   */
  haptic(action, { nmPerMm, pullOffAtHandN } = {}, id) {
    if (!['engage', 'release', 'recenter', 'scale'].includes(action)) throw new RangeError(`action must be engage, release, recenter or scale, got ${JSON.stringify(action)}`);
    const m = { type: 'haptic', action };
    if (action === 'scale') {
      if (nmPerMm === undefined && pullOffAtHandN === undefined) throw new RangeError('scale needs nm_per_mm and/or pull_off_at_hand_n');
      if (nmPerMm !== undefined) {
        finite('nm_per_mm', nmPerMm);
        if (!(nmPerMm >= 0.01 && nmPerMm <= 1000)) throw new RangeError(`nm_per_mm must be in [0.01, 1000] nm/mm, got ${nmPerMm}`);
        m.nm_per_mm = nmPerMm;
      }
      if (pullOffAtHandN !== undefined) {
        finite('pull_off_at_hand_n', pullOffAtHandN);
        if (!(pullOffAtHandN >= 0.01 && pullOffAtHandN <= 10)) throw new RangeError(`pull_off_at_hand_n must be in [0.01, 10] N, got ${pullOffAtHandN}`);
        m.pull_off_at_hand_n = pullOffAtHandN;
      }
    }
    return withId(m, id);
  },
  ping(id) {
    return withId({ type: 'ping' }, id);
  },
  /**
   * The newest telemetry frame read (its `seq`, an integer ≥ 1): the server keeps no more frames
   * in flight than the page reads in half a second. Not answered, so it carries no id.
   */
  ack(seq) {
    if (!Number.isSafeInteger(seq) || seq < 1) throw new RangeError(`seq must be a telemetry frame's seq (an integer ≥ 1), got ${seq}`);
    return { type: 'ack', seq };
  },
};

/**
 * A push's tolerance as the server checks it, from its `welcome` (`push_tolerance_nm`): `{default,
 * min, max}` in nm, or null when the welcome says none (an older server, the demo) or says
 * something that is not a range about its default.
 */
export function pushTolerance(welcome) {
  const b = welcome?.push_tolerance_nm;
  const ok = b && [b.default, b.min, b.max].every(Number.isFinite) && b.min <= b.default && b.default <= b.max;
  return ok ? { default: b.default, min: b.min, max: b.max } : null;
}

/** The JSON text of a client message. */
export function encodeCommand(msg) {
  if (!msg || typeof msg.type !== 'string') throw new TypeError('encodeCommand: a message needs a type');
  return JSON.stringify(msg);
}
