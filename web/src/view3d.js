// The 3D view: the stage substrate with the scene's particles (src/particles3d.js), the latest
// scan as a height-map surface filled line by line (src/surface3d.js), the cantilever tip as a
// ball (src/tip3d.js) and the push's marks (src/marks3d.js). Loaded only when first opened
// (src/view3dhost.js keeps its place and what it is to show until then). This module holds them
// together: the renderer, the camera and its framing, the stage, the height exaggeration and
// picking. World units: µm in x and y, µm × exaggeration in z (z up). Renders on demand (the
// machine may have no GPU): it registers with the page's frame scheduler (src/frame.js), which
// draws it in an animation frame after a change and, after a slow frame, waits as long as that
// frame took.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { CSS2DRenderer } from 'three/addons/renderers/CSS2DRenderer.js';
import { ScanSurface, MAX_SIDE, MAX_SIDE_SOFTWARE } from './surface3d.js';
import { ParticleSpheres } from './particles3d.js';
import { TipMarker } from './tip3d.js';
import { PushMarks } from './marks3d.js';
import { softwareGl } from './view3dhost.js';

/**
 * Where a camera of vertical field `fovDeg` and `aspect` stands to see the box (x0, y0, w, h) µm
 * on the substrate: from the south, 42° up, far enough that the whole box fits the narrower of
 * the two fields of view with a margin (counting only the vertical field cuts a tall, narrow
 * view's edges off). {target, position: [x, y, z] µm, near, far}.
 */
export function framingPose(fovDeg, aspect, x0, y0, w, h) {
  const cx = x0 + w / 2;
  const cy = y0 + h / 2;
  const vHalf = ((fovDeg / 2) * Math.PI) / 180;
  const hHalf = Math.atan(Math.tan(vHalf) * aspect);
  const radius = 0.5 * Math.hypot(w, h); // the box's corners, seen from any side
  const dist = (radius * 1.08) / Math.sin(Math.min(vHalf, hHalf));
  const d = dist / Math.hypot(0.95, 0.85);
  return { target: [cx, cy, 0], position: [cx, cy - d * 0.95, d * 0.85], near: d / 1000, far: d * 50 };
}

export class View3D {
  /**
   * @param {HTMLElement} container
   * @param {{onPickPoint?: (xUm:number, yUm:number) => void, onPickParticle?: (id:number) => void}} handlers
   * @param {import('./frame.js').FrameScheduler} scheduler the page's animation-frame loop
   * @param {{software?: boolean, slot?: () => number}} [opts] whether WebGL runs on a software
   *   renderer (asked when not given); the page's live slot (ms: src/frame.js liveSlotMs), the
   *   tip's moves drawn once in each
   */
  constructor(container, handlers, scheduler, { software, slot = () => 0 } = {}) {
    this.container = container;
    this.handlers = handlers ?? {};
    this.exaggeration = 1;
    this.stageUm = 100;
    // Render on change, at most once per animation frame; when a frame is slow (a software
    // renderer, a big scan), wait as long as it took before the next, so at least half of the
    // main thread stays free for input (a Stop click is never queued behind frames).
    this.scheduler = scheduler;
    this.frame = scheduler.register('view3d', (parts, now) => this.render(now), { waitAfterSlow: true });
    this.frame.mark();

    // A software renderer (SwiftShader, llvmpipe: no GPU) gets no multisampling, one pixel per
    // CSS pixel and a coarser surface: each frame costs it a fraction.
    this.software = software ?? softwareGl();
    // The tip's moves are drawn in the page's live slots (src/frame.js, liveSlotMs), in the same
    // frames as the map's: on a software renderer each frame that changes costs a whole frame's
    // composite in the browser's GPU process, whatever changed in it.
    this.tipFrame = scheduler.register('view3d-tip', (parts, now) => this.render(now), { period: slot, aligned: true });
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

    this.particles = new ParticleSpheres(this.zGroup);
    this.tip = new TipMarker(this.scene, this.zGroup);
    this.marks = new PushMarks(this.scene, this.zGroup);
    this.surface = new ScanSurface(this.zGroup, { maxSide: this.software ? MAX_SIDE_SOFTWARE : MAX_SIDE });

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

  /** Draws the scene (called by the frame scheduler when something changed), once a frame. */
  render(now) {
    if (this.shown === false || (now !== undefined && now === this.renderedAt)) return;
    this.renderedAt = now;
    this.tip.scaleToScreen(this.camera, this.container.clientHeight);
    this.renderer.render(this.scene, this.camera);
    this.labels.render(this.scene, this.camera);
    this.surface.uploaded();
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

  /** Puts the substrate and its grid at height `zUm` (below the scan). */
  setFloor(zUm) {
    this.substrate.position.z = zUm;
    if (this.grid) this.grid.position.z = zUm;
  }

  /** Display radius (µm) of a marker, so that tiny things stay visible. */
  markerUm() {
    return (this.surface.sideUm() ?? this.stageUm) / 120;
  }

  setExaggeration(x) {
    this.exaggeration = x;
    this.zGroup.scale.z = x;
    this.surface.boundsDirty = true;
    if (this.tip.last) this.setTip(this.tip.last, false);
    this.marks.setExaggeration(x);
    this.requestRender();
  }

  // ----- the particles -----

  /** The scene's particles as translucent spheres labelled with their ids. */
  setParticles(particles, selectedId = null) {
    this.particles.set(particles, selectedId, this.stageUm, !!this.surface.mesh);
    this.requestRender();
  }

  /** Moves the spheres to the particles' positions and highlights the selected one. */
  updateParticles(particles, selectedId = null) {
    this.particles.update(particles, selectedId, !!this.surface.mesh);
    this.requestRender();
  }

  particleCentre(id) {
    return this.particles.centre(id);
  }

  // ----- the scan -----

  /** A new scan: an empty surface over its region, filled as lines arrive. */
  startScan(scan) {
    this.surface.start(scan);
    this.requestRender();
  }

  /** Writes line `line` (0 = lowest y) of `scan` (the Session's scan state) into the surface. */
  scanLine(scan, line) {
    if (!this.surface.line(scan, line)) return;
    // Keep the substrate and grid below the scan, so they do not show through its low parts.
    this.setFloor(this.surface.floorUm(scan.min));
    this.requestRender();
  }

  /** A whole scan at once (a record opened, or fetched by a late joiner). */
  fillScan(scan) {
    if (!this.surface.shows(scan)) this.startScan(scan);
    this.surface.fill(scan);
    this.setFloor(this.surface.floorUm(scan.min));
    this.requestRender();
  }

  /**
   * Colours the surface by the height image's levelled heights and its colour scale (`values`
   * indexed as the scan's heights, `lo`, `hi` in m), so one colour means one height in both
   * views; null: by the raw heights.
   */
  setColourSource(src) {
    if (this.surface.setColourSource(src)) this.requestRender();
  }

  /** The colour scale now in use (m), for the legend: the height image's when coloured by it. */
  colourScale() {
    return this.surface.colourScale();
  }

  // ----- the tip -----

  /** Telemetry: the tip ball at the stage position (apex height, exaggerated like the scan). */
  setTip(tip, addTrail = true) {
    const changed = this.tip.set(tip, {
      markerUm: this.markerUm(),
      exaggeration: this.exaggeration,
      surfaceUnder: (x, y) => this.surface.heightUnder(x, y),
      addTrail,
    });
    if (changed) this.tipFrame.mark();
  }

  clearTrail() {
    this.tip.clearTrail();
    this.requestRender();
  }

  // ----- targets, previews and the push -----

  setTarget(xUm, yUm) {
    this.marks.setTarget(xUm, yUm, this.markerUm());
    this.requestRender();
  }

  /** A push preview arrow from (x, y) µm, `lengthUm` along `deg`; null hides it. */
  setPreview(from, deg, lengthUm) {
    this.marks.setPreview(from, deg, lengthUm, this.markerUm(), this.exaggeration);
    this.requestRender();
  }

  /** The commanded push path (points in m), drawn for everyone; null hides it. */
  setPushPath(path) {
    this.marks.setPushPath(path, this.markerUm());
    this.requestRender();
  }

  // ----- camera -----

  /** Looks at the box (x0, y0, w, h) µm: see `framingPose`. */
  frameBox(x0, y0, w, h) {
    const pose = framingPose(this.camera.fov, this.camera.aspect, x0, y0, w, h);
    this.controls.target.set(...pose.target);
    this.camera.position.set(...pose.position);
    this.camera.near = pose.near;
    this.camera.far = pose.far;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.requestRender();
  }

  frameStage() {
    this.frameBox(0, 0, this.stageUm, this.stageUm);
  }

  frameScan() {
    const r = this.surface.regionUm();
    if (!r) return this.frameStage();
    this.frameBox(r.x0, r.y0, r.w, r.h);
  }

  /** Centres the camera on the tip. */
  frameTip() {
    if (!this.tip.ball.visible) return;
    const p = this.tip.ball.position;
    const s = this.surface.sideUm() ?? this.stageUm / 5;
    this.frameBox(p.x - s / 2, p.y - s / 2, s, s);
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

  /** A click: a particle under it, else the point of the scan (or the substrate) under it. */
  pick(clientX, clientY) {
    const rect = this.labels.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const hitP = this.raycaster.intersectObjects([...this.particles.meshes.values()], false)[0];
    if (hitP && this.handlers.onPickParticle) {
      this.handlers.onPickParticle(hitP.object.userData.id);
      return;
    }
    const targets = [this.substrate];
    const surface = this.surface.pickable();
    if (surface) targets.unshift(surface);
    const hit = this.raycaster.intersectObjects(targets, false)[0];
    if (hit && this.handlers.onPickPoint) this.handlers.onPickPoint(hit.point.x, hit.point.y);
  }
}
