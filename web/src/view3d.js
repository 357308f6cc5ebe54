// The 3D view: the stage substrate with the scene's particles, the latest scan as a height-map
// surface filled line by line, and the cantilever tip as a ball. World units: µm in x and y,
// µm × exaggeration in z (z up). Renders on demand (the machine may have no GPU): it registers
// with the page's frame scheduler (src/frame.js), which draws it in an animation frame after a
// change and, after a slow frame, waits as long as that frame took.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { CSS2DRenderer, CSS2DObject } from 'three/addons/renderers/CSS2DRenderer.js';
import { viridisTable } from './colormap.js';
import { formatLength } from './format.js';

const UM = 1e6; // metres → µm
const LUT_N = 256;
const TRAIL_N = 900;
/** Most vertices per side of the 3D surface: a 512² scan is drawn from every 4th pixel (the 2D
 * image keeps every pixel); 65k vertices is what a software renderer draws at a usable rate. */
const MAX_SIDE = 160;
/** Smallest on-screen radius of the tip ball (CSS px), however far the camera is. */
const TIP_MIN_PX = 7;

export class View3D {
  /**
   * @param {HTMLElement} container
   * @param {{onPickPoint?: (xUm:number, yUm:number) => void, onPickParticle?: (id:number) => void}} handlers
   * @param {import('./frame.js').FrameScheduler} scheduler the page's animation-frame loop
   */
  constructor(container, handlers, scheduler) {
    this.container = container;
    this.handlers = handlers ?? {};
    this.exaggeration = 1;
    this.stageUm = 100;
    // Render on change, at most once per animation frame; when a frame is slow (a software
    // renderer, a big scan), wait as long as it took before the next, so at least half of the
    // main thread stays free for input (a Stop click is never queued behind frames).
    this.scheduler = scheduler;
    this.frame = scheduler.register('view3d', () => this.render(), { waitAfterSlow: true });
    this.frame.mark();

    // A software renderer (SwiftShader, llvmpipe: no GPU) gets no multisampling and one pixel
    // per CSS pixel: each frame costs it a fraction.
    this.software = softwareGl();
    this.renderer = new THREE.WebGLRenderer({ antialias: !this.software });
    this.renderer.setPixelRatio(this.software ? 1 : Math.min(2, window.devicePixelRatio || 1));
    this.renderer.setClearColor(0x10141a);
    container.appendChild(this.renderer.domElement);
    this.renderer.domElement.setAttribute('aria-hidden', 'true');
    this.labels = new CSS2DRenderer();
    this.labels.domElement.className = 'labels';
    container.appendChild(this.labels.domElement);

    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 20000);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera, this.labels.domElement);
    this.controls.addEventListener('change', () => this.requestRender());

    // Everything whose height is exaggerated lives in zGroup (scale.z = exaggeration).
    this.zGroup = new THREE.Group();
    this.scene.add(this.zGroup);

    this.substrate = new THREE.Mesh(
      new THREE.PlaneGeometry(1, 1),
      new THREE.MeshBasicMaterial({ color: 0x1b222b, polygonOffset: true, polygonOffsetFactor: 2, polygonOffsetUnits: 2 }),
    );
    this.zGroup.add(this.substrate);
    this.grid = null;

    this.particleGroup = new THREE.Group();
    this.zGroup.add(this.particleGroup);
    this.particleMeshes = new Map();

    // The tip: a ball, a drop line to the substrate and a trail of recent positions.
    // Drawn last and through everything (the scan, particles): the operator must always see
    // where the tip is; a ring and a shadow on the substrate mark it from above too.
    this.tip = new THREE.Mesh(new THREE.SphereGeometry(1, 24, 16), new THREE.MeshBasicMaterial({ color: 0xff7a3d, depthTest: false, depthWrite: false }));
    this.tip.renderOrder = 1000;
    this.tip.visible = false;
    this.scene.add(this.tip);
    this.tipRing = new THREE.Mesh(new THREE.RingGeometry(1.25, 1.6, 32), new THREE.MeshBasicMaterial({ color: 0xffd0b0, side: THREE.DoubleSide, depthTest: false, depthWrite: false }));
    this.tipRing.renderOrder = 1001;
    this.tip.add(this.tipRing);
    this.tipShadow = new THREE.Mesh(new THREE.CircleGeometry(1, 32), new THREE.MeshBasicMaterial({ color: 0x000000, transparent: true, opacity: 0.55, depthTest: false, depthWrite: false }));
    this.tipShadow.renderOrder = 999;
    this.tipShadow.visible = false;
    this.scene.add(this.tipShadow);
    this.dropGeom = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(new Float32Array(6), 3));
    this.drop = new THREE.Line(this.dropGeom, new THREE.LineDashedMaterial({ color: 0xff9a66, dashSize: 0.3, gapSize: 0.2 }));
    this.drop.visible = false;
    this.scene.add(this.drop);
    this.trailPos = new Float32Array(TRAIL_N * 3);
    this.trailLen = 0;
    const tg = new THREE.BufferGeometry();
    tg.setAttribute('position', new THREE.BufferAttribute(this.trailPos, 3).setUsage(THREE.DynamicDrawUsage));
    tg.setDrawRange(0, 0);
    this.trail = new THREE.Line(tg, new THREE.LineBasicMaterial({ color: 0xffa070, transparent: true, opacity: 0.55 }));
    this.trail.frustumCulled = false;
    this.zGroup.add(this.trail);

    // The pushed particle's estimate (telemetry), a target marker and a push preview.
    this.estimate = new THREE.Mesh(new THREE.RingGeometry(0.8, 1, 40), new THREE.MeshBasicMaterial({ color: 0x7fe3ff, side: THREE.DoubleSide }));
    this.estimate.visible = false;
    this.zGroup.add(this.estimate);
    this.target = new THREE.Group();
    const tm = new THREE.MeshBasicMaterial({ color: 0xff4fa3, side: THREE.DoubleSide });
    this.target.add(new THREE.Mesh(new THREE.RingGeometry(0.7, 1, 40), tm));
    this.target.add(new THREE.Mesh(new THREE.PlaneGeometry(2.6, 0.18), tm));
    this.target.add(new THREE.Mesh(new THREE.PlaneGeometry(0.18, 2.6), tm));
    this.target.visible = false;
    this.zGroup.add(this.target);
    this.preview = new THREE.ArrowHelper(new THREE.Vector3(1, 0, 0), new THREE.Vector3(), 1, 0xff4fa3);
    this.preview.visible = false;
    this.scene.add(this.preview);
    // The commanded push (everyone sees it): the planned path of the particle's centre.
    this.pushPath = new THREE.Group();
    this.pushPath.visible = false;
    this.scene.add(this.pushPath);
    this.pushPathPoints = null;

    // The scan.
    this.scanMesh = null;
    this.scanOutline = null;
    this.scanBoundsDirty = false;
    this.lut = this.buildLut();
    this.colourRange = null;

    this.raycaster = new THREE.Raycaster();
    this.bindPicking();
    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(container);
    this.resize();
    this.setStage(100);
    this.frameStage();
  }

  /**
   * Shown or hidden (the 3D view is the height image's optional companion): hidden, it is not
   * rendered at all; shown again, it is sized and drawn in the next frame.
   */
  setShown(on) {
    this.shown = on;
    if (on) this.resize();
  }

  /** Draws the scene (called by the frame scheduler when something changed). */
  render() {
    if (this.shown === false) return;
    this.scaleTip();
    this.renderer.render(this.scene, this.camera);
    this.labels.render(this.scene, this.camera);
    this.colourFull = false;
    this.posFull = false;
  }

  requestRender() {
    this.frame.mark();
  }

  /** Frames rendered so far. */
  get frames() {
    return this.frame.frames;
  }

  /** How long the last render took (ms of main thread). */
  get renderMs() {
    return this.frame.ms;
  }

  /** ms between animation frames, smoothed: how busy the browser is (the scheduler's measure). */
  get frameInterval() {
    return this.scheduler.frameInterval;
  }

  buildLut() {
    const srgb = viridisTable(LUT_N);
    const out = new Float32Array(srgb.length);
    const c = new THREE.Color();
    for (let i = 0; i < LUT_N; i++) {
      c.setRGB(srgb[3 * i], srgb[3 * i + 1], srgb[3 * i + 2], THREE.SRGBColorSpace);
      out[3 * i] = c.r;
      out[3 * i + 1] = c.g;
      out[3 * i + 2] = c.b;
    }
    return out;
  }

  resize() {
    const w = Math.max(1, this.container.clientWidth);
    const h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h);
    this.labels.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  /** The stage: a substrate plane of range × range µm with a 10 µm grid. */
  setStage(rangeUm) {
    this.stageUm = rangeUm;
    this.substrate.scale.set(rangeUm, rangeUm, 1);
    this.substrate.position.set(rangeUm / 2, rangeUm / 2, 0);
    if (this.grid) this.zGroup.remove(this.grid);
    const pts = [];
    const step = rangeUm >= 50 ? 10 : rangeUm >= 10 ? 1 : rangeUm / 10;
    for (let v = 0; v <= rangeUm + 1e-9; v += step) {
      pts.push(v, 0, 0, v, rangeUm, 0, 0, v, 0, rangeUm, v, 0);
    }
    const g = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(pts, 3));
    // #8796aa on the #1b222b substrate: 5:1 contrast.
    this.grid = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: 0x8796aa }));
    this.zGroup.add(this.grid);
    this.requestRender();
  }

  /** Display radius (µm) of a marker, so that tiny things stay visible. */
  markerUm() {
    const s = this.scanMesh ? Math.max(this.scanMesh.userData.wUm, this.scanMesh.userData.hUm) : this.stageUm;
    return s / 120;
  }

  /** The scene's particles as translucent spheres labelled with their ids. */
  setParticles(particles, selectedId = null) {
    for (const m of this.particleMeshes.values()) {
      this.particleGroup.remove(m);
      m.traverse((o) => o.isCSS2DObject && o.element.remove());
    }
    this.particleMeshes.clear();
    for (const p of particles) {
      const rUm = p.radius * UM;
      const shown = Math.max(rUm, this.stageUm / 250);
      const mesh = new THREE.Mesh(
        new THREE.SphereGeometry(1, 32, 20),
        new THREE.MeshBasicMaterial({ color: 0xe6c35c, transparent: true, opacity: 0.45, depthWrite: false }),
      );
      mesh.scale.setScalar(shown);
      mesh.userData = { id: p.id, rUm, shown };
      const el = document.createElement('div');
      el.className = 'plabel';
      el.textContent = `#${p.id}`;
      el.title = `particle ${p.id}${p.material ? ` (${p.material})` : ''}, radius ${formatLength(p.radius)}`;
      const label = new CSS2DObject(el);
      // Beside the sphere, not over it (where the tip works), and see-through.
      label.position.set(1.15, 0, 0);
      label.center.set(0, 0.5);
      mesh.add(label);
      this.particleGroup.add(mesh);
      this.particleMeshes.set(p.id, mesh);
    }
    this.updateParticles(particles, selectedId);
  }

  /** Moves the spheres to the particles' positions and highlights the selected one. */
  updateParticles(particles, selectedId = null) {
    for (const p of particles) {
      const m = this.particleMeshes.get(p.id);
      if (!m) continue;
      m.position.set(p.x * UM, p.y * UM, m.userData.rUm);
      const sel = p.id === selectedId;
      m.material.color.set(sel ? 0xffe08a : 0xe6c35c);
      m.material.opacity = (sel ? 0.6 : 0.4) * (this.scanMesh ? 0.5 : 1);
      m.children[0].element.classList.toggle('selected', sel);
    }
    this.requestRender();
  }

  particleCentre(id) {
    const m = this.particleMeshes.get(id);
    return m ? m.position : null;
  }

  setExaggeration(x) {
    this.exaggeration = x;
    this.zGroup.scale.z = x;
    this.scanBoundsDirty = true;
    if (this.lastTip) this.setTip(this.lastTip, false);
    this.updatePreviewZ();
    this.requestRender();
  }

  // ----- the scan -----

  /** A new scan: an empty surface over its region, filled as lines arrive. */
  startScan(scan) {
    this.clearScan();
    this.scanState = scan;
    const { xres, yres } = scan;
    const wUm = scan.x_real * UM;
    const hUm = scan.y_real * UM;
    // Vertices at the centres of every `step`-th pixel (nx × ny of them).
    const { step, nx, ny } = surfaceGrid(xres, yres);
    const spanX = wUm * ((nx - 1) * step) / xres;
    const spanY = hUm * ((ny - 1) * step) / yres;
    const geom = new THREE.PlaneGeometry(spanX, spanY, nx - 1, ny - 1);
    const pos = geom.getAttribute('position');
    pos.setUsage(THREE.DynamicDrawUsage);
    const col = new THREE.BufferAttribute(new Float32Array(nx * ny * 3), 3);
    col.setUsage(THREE.DynamicDrawUsage);
    geom.setAttribute('color', col);
    geom.setDrawRange(0, 0);
    const mesh = new THREE.Mesh(geom, new THREE.MeshBasicMaterial({ vertexColors: true, side: THREE.DoubleSide }));
    mesh.position.set(scan.x_offset * UM + (wUm / xres) * 0.5 + spanX / 2, scan.y_offset * UM + (hUm / yres) * 0.5 + spanY / 2, 0);
    mesh.userData = { wUm, hUm, xres, yres, nx, ny, step, scanId: scan.id };
    this.scanMesh = mesh;
    this.zGroup.add(mesh);
    this.posFull = true;
    this.colourFull = true;
    this.colourRange = null;

    const x0 = scan.x_offset * UM;
    const y0 = scan.y_offset * UM;
    const og = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(
      [x0, y0, 0, x0 + wUm, y0, 0, x0 + wUm, y0 + hUm, 0, x0, y0 + hUm, 0], 3));
    this.scanOutline = new THREE.LineLoop(og, new THREE.LineBasicMaterial({ color: 0x7fe3ff }));
    this.zGroup.add(this.scanOutline);
    this.requestRender();
  }

  clearScan() {
    for (const o of [this.scanMesh, this.scanOutline]) {
      if (o) {
        this.zGroup.remove(o);
        o.geometry.dispose();
        o.material.dispose();
      }
    }
    this.scanMesh = null;
    this.scanOutline = null;
  }

  /** Writes line `line` (0 = lowest y) of `scan` (the Session's scan state) into the surface. */
  scanLine(scan, line) {
    const mesh = this.scanMesh;
    if (!mesh || mesh.userData.scanId !== scan.id) return;
    const { yres } = scan;
    const { nx, ny, step } = mesh.userData;
    const geom = mesh.geometry;
    const pos = geom.getAttribute('position');
    const onMesh = line % step === 0 && line / step < ny;
    const row = ny - 1 - line / step; // PlaneGeometry rows run from +y down
    if (onMesh) {
      this.writeRow(scan, line / step);
      // Upload just this row, unless a full upload is pending (a new scan) until the next
      // render: a range added now would narrow it.
      if (!this.posFull) pos.addUpdateRange(row * nx * 3, nx * 3);
      pos.needsUpdate = true;
    }

    // Colour by height: recolour everything when the range grows by more than 2 %.
    const lo = scan.min;
    const hi = scan.max;
    const r = this.colourRange;
    const span = Math.max(hi - lo, 1e-12);
    if (!r || lo < r.lo - 0.02 * span || hi > r.hi + 0.02 * span) {
      this.colourRange = { lo: lo - 0.01 * span, hi: hi + 0.01 * span };
      this.recolour(scan);
    } else if (onMesh) {
      this.colourRow(scan, line / step);
      const col = geom.getAttribute('color');
      // A full upload pending (after a recolour) must not be narrowed to this row.
      if (!this.colourFull) col.addUpdateRange(row * nx * 3, nx * 3);
      col.needsUpdate = true;
    }

    // Keep the substrate and grid below the scan, so they do not show through its low parts.
    const floor = Math.min(0, lo * UM) - 0.002 * Math.max(mesh.userData.wUm, 1e-3);
    this.substrate.position.z = floor;
    if (this.grid) this.grid.position.z = floor;

    this.updateDrawRange(scan);
  }

  /** Writes mesh row `b` (scan line b·step) into the positions. */
  writeRow(scan, b) {
    const { xres } = scan;
    const { nx, ny, step } = this.scanMesh.userData;
    const arr = this.scanMesh.geometry.getAttribute('position').array;
    const row = ny - 1 - b;
    const line = b * step;
    for (let a = 0; a < nx; a++) {
      const h = scan.heights[line * xres + Math.min(xres - 1, a * step)];
      arr[3 * (row * nx + a) + 2] = Number.isFinite(h) ? h * UM : 0;
    }
  }

  /** Draws the quads between contiguous received mesh rows from the bottom. */
  updateDrawRange(scan) {
    const { nx, ny, step } = this.scanMesh.userData;
    let k = 0;
    while (k < scan.yres && scan.received[k]) k++;
    // Mesh rows b with b·step < k are in.
    const rows = Math.min(ny, Math.ceil(k / step));
    const quadRows = Math.max(0, rows - 1);
    const total = (ny - 1) * (nx - 1) * 6;
    this.scanMesh.geometry.setDrawRange(total - quadRows * (nx - 1) * 6, quadRows * (nx - 1) * 6);
    this.scanBoundsDirty = true;
    this.requestRender();
  }

  /** A whole scan at once (a record opened, or fetched by a late joiner). */
  fillScan(scan) {
    if (!this.scanMesh || this.scanMesh.userData.scanId !== scan.id) this.startScan(scan);
    const { ny } = this.scanMesh.userData;
    for (let b = 0; b < ny; b++) this.writeRow(scan, b);
    const pos = this.scanMesh.geometry.getAttribute('position');
    pos.clearUpdateRanges();
    pos.needsUpdate = true;
    this.posFull = true;
    const span = Math.max(scan.max - scan.min, 1e-12);
    this.colourRange = { lo: scan.min - 0.01 * span, hi: scan.max + 0.01 * span };
    this.recolour(scan);
    const floor = Math.min(0, scan.min * UM) - 0.002 * Math.max(this.scanMesh.userData.wUm, 1e-3);
    this.substrate.position.z = floor;
    if (this.grid) this.grid.position.z = floor;
    this.updateDrawRange(scan);
  }

  /**
   * Colours by the height image's levelled heights and its colour scale (`values` indexed as the
   * scan's heights, `lo`, `hi` in m), so one colour means one height in both views; null: by
   * the raw heights (the shape is always the raw heights).
   */
  setColourSource(src) {
    this.colourSource = src;
    const scan = this.scanState;
    if (this.scanMesh && scan && (!src || src.values.length === scan.xres * scan.yres)) {
      this.recolour(scan);
      this.requestRender();
    }
  }

  /** Colours mesh row `b` (scan line b·step). */
  colourRow(scan, b) {
    const { xres } = scan;
    const { nx, ny, step } = this.scanMesh.userData;
    const col = this.scanMesh.geometry.getAttribute('color').array;
    const src = this.colourSource && this.colourSource.values.length === xres * scan.yres ? this.colourSource : null;
    const { lo, hi } = src ?? this.colourRange;
    const heights = src ? src.values : scan.heights;
    const inv = (LUT_N - 1) / Math.max(hi - lo, 1e-18);
    const row = ny - 1 - b;
    const line = b * step;
    for (let a = 0; a < nx; a++) {
      const h = heights[line * xres + Math.min(xres - 1, a * step)];
      let k = Math.round((h - lo) * inv);
      k = k > 0 ? (k < LUT_N ? k : LUT_N - 1) : 0;
      const o = 3 * (row * nx + a);
      col[o] = this.lut[3 * k];
      col[o + 1] = this.lut[3 * k + 1];
      col[o + 2] = this.lut[3 * k + 2];
    }
  }

  recolour(scan) {
    const { ny, step } = this.scanMesh.userData;
    for (let b = 0; b < ny; b++) if (scan.received[b * step]) this.colourRow(scan, b);
    const col = this.scanMesh.geometry.getAttribute('color');
    col.clearUpdateRanges();
    col.needsUpdate = true;
    this.colourFull = true;
  }

  /** The colour scale now in use (m), for the legend: the height image's when coloured by it. */
  colourScale() {
    const src = this.colourSource;
    const scan = this.scanState;
    return src && scan && src.values.length === scan.xres * scan.yres ? { lo: src.lo, hi: src.hi } : this.colourRange;
  }

  // ----- the tip -----

  /** Telemetry: the tip ball at the stage position (apex height, exaggerated like the scan). */
  setTip(tip, addTrail = true) {
    // An idle tip (the same position, 60 times a second) costs no frame.
    const same = tip && this.lastTip && addTrail && tip.stage.every((v, i) => v === this.lastTip.stage[i]) &&
      String(tip.estimate) === String(this.lastTip.estimate);
    if (same) return;
    this.lastTip = tip;
    if (!tip) {
      this.tip.visible = false;
      this.drop.visible = false;
      this.estimate.visible = false;
      this.requestRender();
      return;
    }
    const [x, y, z] = tip.stage;
    const r = this.markerUm() * 0.6;
    const xu = x * UM;
    const yu = y * UM;
    const zu = z * UM;
    this.tip.visible = true;
    this.tipR = r;
    this.tip.scale.setScalar(r);
    this.tip.position.set(xu, yu, zu * this.exaggeration + r);
    this.tipShadow.visible = true;
    this.tipShadow.position.set(xu, yu, this.surfaceUnder(xu, yu) * this.exaggeration);
    const d = this.dropGeom.getAttribute('position');
    d.setXYZ(0, xu, yu, zu * this.exaggeration);
    d.setXYZ(1, xu, yu, this.surfaceUnder(xu, yu) * this.exaggeration);
    d.needsUpdate = true;
    this.drop.computeLineDistances();
    this.drop.material.dashSize = r * 0.6;
    this.drop.material.gapSize = r * 0.4;
    this.drop.visible = true;
    if (addTrail) {
      if (this.trailLen === TRAIL_N) {
        this.trailPos.copyWithin(0, 3);
        this.trailLen--;
      }
      this.trailPos.set([xu, yu, zu], 3 * this.trailLen);
      this.trailLen++;
      const a = this.trail.geometry.getAttribute('position');
      a.needsUpdate = true;
      this.trail.geometry.setDrawRange(0, this.trailLen);
    }
    if (tip.estimate) {
      this.estimate.visible = true;
      this.estimate.position.set(tip.estimate[0] * UM, tip.estimate[1] * UM, 0.01);
      this.estimate.scale.setScalar(r * 2);
    } else {
      this.estimate.visible = false;
    }
    this.requestRender();
  }

  /** Keeps the tip ball at least TIP_MIN_PX on screen, however far the camera is. */
  scaleTip() {
    if (!this.tip.visible) return;
    const h = Math.max(1, this.container.clientHeight);
    const dist = this.camera.position.distanceTo(this.tip.position);
    const perPx = (2 * dist * Math.tan((this.camera.fov * Math.PI) / 360)) / h;
    const r = Math.max(this.tipR ?? 0, TIP_MIN_PX * perPx);
    this.tip.scale.setScalar(r);
    this.tipShadow.scale.setScalar(r * 1.1);
  }

  /** Centres the camera on the tip. */
  frameTip() {
    if (!this.tip.visible) return;
    const p = this.tip.position;
    const s = this.scanMesh ? Math.max(this.scanMesh.userData.wUm, this.scanMesh.userData.hUm) : this.stageUm / 5;
    this.frameBox(p.x - s / 2, p.y - s / 2, s, s);
  }

  /** The commanded push path (points in m), drawn for everyone; null hides it. */
  setPushPath(path) {
    while (this.pushPath.children.length) {
      const c = this.pushPath.children.pop();
      c.geometry?.dispose();
    }
    this.pushPathPoints = path && path.length >= 2 ? path.map(([x, y]) => [x * UM, y * UM]) : null;
    if (!this.pushPathPoints) {
      this.pushPath.visible = false;
      this.requestRender();
      return;
    }
    const z = Math.max(0.05, this.markerUm() * 0.2);
    const pts = this.pushPathPoints.map(([x, y]) => new THREE.Vector3(x, y, z));
    const mat = new THREE.LineBasicMaterial({ color: 0x4fd1ff, depthTest: false });
    const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts), mat);
    line.renderOrder = 998;
    this.pushPath.add(line);
    const a = pts[pts.length - 2];
    const b = pts[pts.length - 1];
    const d = new THREE.Vector3().subVectors(b, a);
    const len = d.length();
    if (len > 0) {
      const head = Math.min(len * 0.4, this.markerUm() * 2.5);
      const arrow = new THREE.ArrowHelper(d.normalize(), b.clone().addScaledVector(d, -head), head, 0x4fd1ff, head, head * 0.6);
      arrow.renderOrder = 998;
      this.pushPath.add(arrow);
    }
    this.pushPath.visible = true;
    this.requestRender();
  }

  clearTrail() {
    this.trailLen = 0;
    this.trail.geometry.setDrawRange(0, 0);
    this.requestRender();
  }

  /** Height (µm, not exaggerated) of the scan under (x, y) µm, or 0 off the scan. */
  surfaceUnder(xu, yu) {
    const m = this.scanMesh;
    if (!m || !this.scanState) return 0;
    const s = this.scanState;
    const fx = (xu - s.x_offset * UM) / (s.x_real * UM);
    const fy = (yu - s.y_offset * UM) / (s.y_real * UM);
    if (fx < 0 || fx >= 1 || fy < 0 || fy >= 1) return 0;
    const i = Math.floor(fx * s.xres);
    const l = Math.floor(fy * s.yres);
    if (!s.received[l]) return 0;
    const h = s.heights[l * s.xres + i];
    return Number.isFinite(h) ? h * UM : 0;
  }

  // ----- targets and previews -----

  setTarget(xUm, yUm) {
    if (xUm === null || xUm === undefined) {
      this.target.visible = false;
    } else {
      this.target.visible = true;
      this.target.position.set(xUm, yUm, 0.02);
      this.target.scale.setScalar(this.markerUm());
    }
    this.requestRender();
  }

  /** A push preview arrow from (x, y) µm, `lengthUm` along `deg`; null hides it. */
  setPreview(from, deg, lengthUm) {
    if (!from || !(lengthUm > 0)) {
      this.preview.visible = false;
      this.requestRender();
      return;
    }
    this.previewArgs = { from, deg, lengthUm };
    const a = (deg * Math.PI) / 180;
    this.preview.setDirection(new THREE.Vector3(Math.cos(a), Math.sin(a), 0));
    const head = Math.min(lengthUm * 0.3, this.markerUm() * 2);
    this.preview.setLength(lengthUm, head, head * 0.6);
    this.preview.visible = true;
    this.updatePreviewZ();
    this.requestRender();
  }

  updatePreviewZ() {
    if (!this.previewArgs || !this.preview.visible) return;
    const { from } = this.previewArgs;
    this.preview.position.set(from.x, from.y, Math.max(0.05, (from.z ?? 0) * this.exaggeration));
  }

  // ----- camera -----

  /**
   * Looks at the box from the south, 42° up, from far enough that the whole box fits the
   * narrower of the two fields of view with a margin (a tall, narrow view cut the scan's edges
   * off when only the vertical field was counted).
   */
  frameBox(x0, y0, w, h) {
    const cx = x0 + w / 2;
    const cy = y0 + h / 2;
    const vHalf = ((this.camera.fov / 2) * Math.PI) / 180;
    const hHalf = Math.atan(Math.tan(vHalf) * this.camera.aspect);
    const radius = 0.5 * Math.hypot(w, h); // the box's corners, seen from any side
    const dist = (radius * 1.08) / Math.sin(Math.min(vHalf, hHalf));
    const d = dist / Math.hypot(0.95, 0.85);
    this.controls.target.set(cx, cy, 0);
    this.camera.position.set(cx, cy - d * 0.95, d * 0.85);
    this.camera.near = d / 1000;
    this.camera.far = d * 50;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.requestRender();
  }

  frameStage() {
    this.frameBox(0, 0, this.stageUm, this.stageUm);
  }

  frameScan() {
    const m = this.scanMesh;
    if (!m) return this.frameStage();
    this.frameBox(m.position.x - m.userData.wUm / 2, m.position.y - m.userData.hUm / 2, m.userData.wUm, m.userData.hUm);
  }

  // ----- picking -----

  bindPicking() {
    const el = this.labels.domElement;
    let down = null;
    el.addEventListener('pointerdown', (e) => {
      down = e.button === 0 ? { x: e.clientX, y: e.clientY } : null;
    });
    el.addEventListener('pointerup', (e) => {
      if (!down || Math.hypot(e.clientX - down.x, e.clientY - down.y) > 4) return;
      down = null;
      this.pick(e.clientX, e.clientY);
    });
  }

  pick(clientX, clientY) {
    const rect = this.labels.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const hitP = this.raycaster.intersectObjects([...this.particleMeshes.values()], false)[0];
    if (hitP && this.handlers.onPickParticle) {
      this.handlers.onPickParticle(hitP.object.userData.id);
      return;
    }
    const targets = [this.substrate];
    if (this.scanMesh) {
      if (this.scanBoundsDirty) {
        this.scanMesh.geometry.computeBoundingSphere();
        this.scanMesh.geometry.computeBoundingBox();
        this.scanBoundsDirty = false;
      }
      targets.unshift(this.scanMesh);
    }
    const hit = this.raycaster.intersectObjects(targets, false)[0];
    if (hit && this.handlers.onPickPoint) this.handlers.onPickPoint(hit.point.x, hit.point.y);
  }
}

/** Whether WebGL runs on a software renderer (SwiftShader, llvmpipe, softpipe). */
function softwareGl() {
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

/** The 3D surface of an `xres × yres` scan: a vertex at every `step`-th pixel, `nx × ny` of
 * them, at most `MAX_SIDE` a side. */
export function surfaceGrid(xres, yres) {
  const step = Math.max(1, Math.ceil(Math.max(xres, yres) / MAX_SIDE));
  return { step, nx: Math.max(2, Math.ceil(xres / step)), ny: Math.max(2, Math.ceil(yres / step)) };
}
