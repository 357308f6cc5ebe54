// The page's one animation-frame loop. Views register a draw function and mark themselves dirty
// when what they show changes (a message, a resize, a drag); each animation frame draws the dirty
// ones, in the order they registered, never once per message. A view may ask to be drawn at most
// every `period` ms, and to wait, after a slow draw, as long as that draw took ("renders on
// change, and after a slow frame waits as long as it took"), so that at least half of the main
// thread stays free for input (a Stop click is never queued behind frames).
//
// The loop runs every frame, dirty or not (as the 3D view's own loop did), so that
// `frameInterval` measures how busy the browser is; a frame with nothing dirty costs a few
// comparisons. No DOM: Node tests drive it with a fake requestAnimationFrame and clock.

/**
 * How often the live views (the tip, its readout, the plots) refresh while frames come every
 * `frameIntervalMs`: every frame while the browser keeps up (≤ 40 ms); when its frames are slow
 * (a software renderer, a busy machine) three frame times apart, at least 250 ms, at most 1 s, so
 * frames stay free for what the operator does: a Stop click and its reply are never queued
 * behind tip updates.
 */
export function livePeriodMs(frameIntervalMs) {
  const f = frameIntervalMs;
  return f > 40 ? Math.min(1000, Math.max(250, 3 * f)) : 0;
}

/**
 * The live views' slot (ms) on a software renderer (no GPU: SwiftShader, llvmpipe), 0 on a GPU.
 * Such a renderer's browser composites the whole page again in its GPU process for each frame in
 * which anything changed, however small (a 12 px dot moved: 42 ms of a 1600×1000 frame on a busy
 * 2-core machine; 12 ms at 800×500; 62 ms with the 3D view shown, and a frame the 3D view is drawn
 * in twice that): the number of frames that change, not what changes in them, sets its frame
 * rate. So the live views (the tip, the pushed particle, the map, the plots, the numbers, the 3D
 * view) change in the same frames, one a slot: 10 a second with the map alone, 5 with the 3D
 * view shown, about half of that process's time.
 */
export function liveSlotMs(software, with3d = false) {
  return software ? (with3d ? 200 : 100) : 0;
}

/**
 * The live views' period (ms) while frames come every `frameIntervalMs`: `livePeriodMs`, and with
 * a slot (`slotMs` > 0: a software renderer) whole slots, at least one (views aligned to them
 * change in the same frames).
 */
export function livePeriodFor(frameIntervalMs, slotMs) {
  const p = livePeriodMs(frameIntervalMs);
  return slotMs ? Math.max(1, Math.ceil(p / slotMs)) * slotMs : p;
}

const report = globalThis.reportError?.bind(globalThis) ?? ((e) => setTimeout(() => { throw e; }));

/** A draw slower than this (ms) makes its view wait as long again before the next. */
export const SLOW_DRAW_MS = 12;

export class FrameScheduler {
  /**
   * @param {{requestFrame?: (cb: (now: number) => void) => unknown, clock?: () => number, onError?: (e: unknown) => void}} [opts]
   *   `requestFrame` defaults to `requestAnimationFrame`, `clock` to `performance.now` (the time
   *   base of the frames' timestamps), `onError` (a draw threw) to reporting it as uncaught.
   */
  constructor({ requestFrame, clock, onError } = {}) {
    this.requestFrame = requestFrame ?? ((cb) => requestAnimationFrame(cb));
    this.clock = clock ?? (() => performance.now());
    this.onError = onError ?? report;
    this.views = [];
    this.running = false;
    this.last = 0; // the previous frame's timestamp
    /** ms between animation frames, smoothed: how busy the browser is. */
    this.frameInterval = 16.7;
    this.frames = 0; // frames run
    this.tick = this.tick.bind(this);
  }

  /**
   * Registers a view; returns its handle: `mark(...parts)` makes it dirty (the parts, any
   * values, are handed to the next draw as a Set), `frames` counts its draws, `ms` is how long
   * the last one took and `totalMs` all of them.
   * @param {string} name
   * @param {(parts: Set<unknown>, now: number) => void} draw
   * @param {{period?: number | (() => number), waitAfterSlow?: boolean, aligned?: boolean}} [opts]
   *   `period`: at least this long (ms) between draws; `aligned`: instead, at most once per
   *   slot of `period` ms of the clock (the first frame in it), so that views whose periods
   *   divide one another draw in the same frames (a software renderer pays for a whole frame
   *   whenever anything changes: the frames between stay clean); `waitAfterSlow`: after a draw
   *   slower than SLOW_DRAW_MS, wait as long as it took.
   */
  register(name, draw, { period = 0, waitAfterSlow = false, aligned = false } = {}) {
    const view = {
      name,
      draw,
      period: typeof period === 'function' ? period : () => period,
      waitAfterSlow,
      aligned,
      dirty: false,
      parts: new Set(),
      lastDraw: -Infinity, // timestamp of the frame that drew it last
      notBefore: 0, // after a slow draw: not before this time
      frames: 0,
      ms: 0,
      totalMs: 0, // all its draws together (the bench's profile: where frames go)
      mark(...parts) {
        view.dirty = true;
        for (const p of parts) view.parts.add(p);
      },
    };
    this.views.push(view);
    return view;
  }

  /** Starts the loop (once). */
  start() {
    if (this.running) return;
    this.running = true;
    this.requestFrame(this.tick);
  }

  /** One animation frame: draws what is dirty and may be drawn now, then asks for the next. */
  tick(now) {
    if (this.last) this.frameInterval += 0.2 * (Math.min(2000, now - this.last) - this.frameInterval);
    this.last = now;
    this.frames++;
    for (const v of this.views) {
      if (!v.dirty || now < v.notBefore) continue;
      const p = v.period();
      if (v.aligned && p > 0 ? Math.floor(now / p) === Math.floor(v.lastDraw / p) : now - v.lastDraw < p) continue;
      const parts = v.parts;
      v.dirty = false;
      v.parts = new Set();
      v.lastDraw = now;
      const t0 = this.clock();
      try {
        v.draw(parts, now);
      } catch (e) {
        // One view's error (reported as uncaught) must not stop the others, or the loop.
        this.onError(e);
      }
      const dt = this.clock() - t0;
      v.ms = dt;
      v.totalMs += dt;
      v.frames++;
      v.notBefore = v.waitAfterSlow && dt > SLOW_DRAW_MS ? this.clock() + dt : 0;
    }
    if (this.running) this.requestFrame(this.tick);
  }
}
