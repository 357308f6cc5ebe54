// The 3D view's place in the page, without three.js: the page talks to this host, which keeps
// what the 3D view would show (the stage, the particles, the scan, its colours, the tip, the push's
// marks, the exaggeration) until the view is first opened; only then is src/view3d.js (three.js,
// most of the page's weight) loaded, built and given all of it, and from then on every call goes
// straight to it. A page whose 3D view stays hidden never downloads three.js.
// `softwareGl` (whether WebGL runs on a software renderer) needs no three.js either: the map
// moves its tip less often on one.

/** Whether WebGL runs on a software renderer (SwiftShader, llvmpipe, softpipe). */
export function softwareGl() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    const ext = gl?.getExtension('WEBGL_debug_renderer_info');
    const name = ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl?.getParameter(gl.RENDERER);
    gl?.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|softpipe|software/i.test(String(name));
  } catch {
    return false;
  }
}

export class View3DHost {
  /**
   * @param {HTMLElement} container where the 3D view goes
   * @param {{onPickPoint?: (xUm:number, yUm:number) => void, onPickParticle?: (id:number) => void}} handlers
   * @param {import('./frame.js').FrameScheduler} scheduler the page's animation-frame loop
   * @param {{load?: () => Promise<{View3D: Function}>, software?: boolean, slot?: () => number}} [opts]
   *   `load`: how the view's module comes (tests give their own); `slot`: the page's live slot
   *   (ms, src/frame.js liveSlotMs), the tip's moves drawn once in each
   */
  constructor(container, handlers, scheduler, { load = () => import('./view3d.js'), software, slot = () => 0 } = {}) {
    this.container = container;
    this.handlers = handlers;
    this.scheduler = scheduler;
    this.load = load;
    this.software = software ?? softwareGl();
    this.slot = slot;
    this.view = null; // the View3D, once opened
    this.loading = null; // its import, while it loads
    this.shown = false;
    // What the view is to show, kept until it exists.
    this.kept = {
      stageUm: 100, particles: [], selected: null, scan: null, colourSource: null, tip: null,
      pushPath: null, preview: null, target: null, exaggeration: 1, framing: 'stage',
    };
  }

  /** Whether three.js has been asked for (the view opened once). */
  get loaded() {
    return this.view !== null;
  }

  /**
   * Shown or hidden. The first time it is shown, the view is loaded and built from what was kept;
   * resolves once it is (at once when it exists or is hidden).
   */
  setShown(on) {
    this.shown = on;
    if (this.view) {
      this.view.setShown(on);
      return Promise.resolve();
    }
    if (!on) return Promise.resolve();
    // (A failed load, the server away, is tried again the next time the view is shown.)
    this.loading ??= this.load().then(({ View3D }) => this.build(View3D), (e) => {
      this.loading = null;
      throw e;
    });
    return this.loading;
  }

  /** Builds the view and gives it everything kept. */
  build(View3D) {
    const k = this.kept;
    const v = new View3D(this.container, this.handlers, this.scheduler, { software: this.software, slot: this.slot });
    v.setStage(k.stageUm);
    v.setExaggeration(k.exaggeration);
    v.setParticles(k.particles, k.selected);
    if (k.scan) v.fillScan(k.scan);
    v.setColourSource(k.colourSource);
    if (k.tip) v.setTip(k.tip);
    v.setPushPath(k.pushPath);
    if (k.preview) v.setPreview(k.preview.from, k.preview.deg, k.preview.lengthUm);
    if (k.target) v.setTarget(k.target[0], k.target[1]);
    if (k.framing === 'scan') v.frameScan();
    else v.frameStage();
    this.view = v;
    v.setShown(this.shown);
  }

  // What the page calls: kept while there is no view, handed on once there is.

  setStage(rangeUm) {
    this.kept.stageUm = rangeUm;
    this.view?.setStage(rangeUm);
  }

  setExaggeration(x) {
    this.kept.exaggeration = x;
    this.view?.setExaggeration(x);
  }

  setParticles(particles, selectedId = null) {
    Object.assign(this.kept, { particles, selected: selectedId });
    this.view?.setParticles(particles, selectedId);
  }

  updateParticles(particles, selectedId = null) {
    Object.assign(this.kept, { particles, selected: selectedId });
    this.view?.updateParticles(particles, selectedId);
  }

  startScan(scan) {
    this.kept.scan = scan;
    this.view?.startScan(scan);
  }

  scanLine(scan, line) {
    this.kept.scan = scan;
    this.view?.scanLine(scan, line);
  }

  fillScan(scan) {
    this.kept.scan = scan;
    this.view?.fillScan(scan);
  }

  setColourSource(src) {
    this.kept.colourSource = src;
    this.view?.setColourSource(src);
  }

  /** The colour scale in use (m), for the legend: the height image's, else the scan's range. */
  colourScale() {
    if (this.view) return this.view.colourScale();
    const { colourSource: c, scan } = this.kept;
    if (c) return { lo: c.lo, hi: c.hi };
    return scan && scan.max >= scan.min ? { lo: scan.min, hi: scan.max } : null;
  }

  setTip(tip) {
    this.kept.tip = tip;
    this.view?.setTip(tip);
  }

  clearTrail() {
    this.view?.clearTrail();
  }

  setTarget(xUm, yUm) {
    this.kept.target = xUm === null || xUm === undefined ? null : [xUm, yUm];
    this.view?.setTarget(xUm, yUm);
  }

  setPreview(from, deg, lengthUm) {
    this.kept.preview = from ? { from, deg, lengthUm } : null;
    this.view?.setPreview(from, deg, lengthUm);
  }

  setPushPath(path) {
    this.kept.pushPath = path;
    this.view?.setPushPath(path);
  }

  frameStage() {
    this.kept.framing = 'stage';
    this.view?.frameStage();
  }

  frameScan() {
    this.kept.framing = 'scan';
    this.view?.frameScan();
  }

  frameTip() {
    this.view?.frameTip();
  }

  /** Frames the 3D view rendered (0 before it exists). */
  get frames() {
    return this.view?.frames ?? 0;
  }

  /** How long its last render took (ms). */
  get renderMs() {
    return this.view?.renderMs ?? 0;
  }
}
