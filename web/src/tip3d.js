// The tip in the 3D view: a ball at the apex, drawn last and through everything (the scan, the
// particles: the operator must always see where the tip is) and never smaller than 7 px on
// screen; a ring and a shadow on the surface below mark it from above too; a dashed drop line to
// the surface, a trail of its recent positions, and the pushed particle's estimate (a ring).
// Updated in place from telemetry. No DOM: runs in Node (tests).
import * as THREE from 'three';

const UM = 1e6; // metres → µm
/** Positions the trail keeps (the newest). */
export const TRAIL_N = 900;
/** Smallest on-screen radius of the tip ball (CSS px), however far the camera is. */
export const TIP_MIN_PX = 7;

export class TipMarker {
  /**
   * @param {THREE.Object3D} scene where the ball, its shadow and the drop line go (their heights
   *   are exaggerated here, by `set`)
   * @param {THREE.Object3D} zGroup the exaggerated group, where the trail and the estimate go
   */
  constructor(scene, zGroup) {
    this.ball = new THREE.Mesh(new THREE.SphereGeometry(1, 24, 16), new THREE.MeshBasicMaterial({ color: 0xff7a3d, depthTest: false, depthWrite: false }));
    this.ball.renderOrder = 1000;
    this.ball.visible = false;
    scene.add(this.ball);
    this.ring = new THREE.Mesh(new THREE.RingGeometry(1.25, 1.6, 32), new THREE.MeshBasicMaterial({ color: 0xffd0b0, side: THREE.DoubleSide, depthTest: false, depthWrite: false }));
    this.ring.renderOrder = 1001;
    this.ball.add(this.ring);
    this.shadow = new THREE.Mesh(new THREE.CircleGeometry(1, 32), new THREE.MeshBasicMaterial({ color: 0x000000, transparent: true, opacity: 0.55, depthTest: false, depthWrite: false }));
    this.shadow.renderOrder = 999;
    this.shadow.visible = false;
    scene.add(this.shadow);
    this.dropGeom = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(new Float32Array(6), 3));
    this.drop = new THREE.Line(this.dropGeom, new THREE.LineDashedMaterial({ color: 0xff9a66, dashSize: 0.3, gapSize: 0.2 }));
    this.drop.visible = false;
    scene.add(this.drop);
    this.trailPos = new Float32Array(TRAIL_N * 3);
    this.trailLen = 0;
    const tg = new THREE.BufferGeometry();
    tg.setAttribute('position', new THREE.BufferAttribute(this.trailPos, 3).setUsage(THREE.DynamicDrawUsage));
    tg.setDrawRange(0, 0);
    this.trail = new THREE.Line(tg, new THREE.LineBasicMaterial({ color: 0xffa070, transparent: true, opacity: 0.55 }));
    this.trail.frustumCulled = false;
    zGroup.add(this.trail);
    this.estimate = new THREE.Mesh(new THREE.RingGeometry(0.8, 1, 40), new THREE.MeshBasicMaterial({ color: 0x7fe3ff, side: THREE.DoubleSide }));
    this.estimate.visible = false;
    zGroup.add(this.estimate);
    this.last = null; // the last telemetry shown
    this.r = null; // the ball's radius (µm) before `scaleToScreen` enlarges it
  }

  /**
   * Telemetry (`tip`: the Session's {stage: [x, y, z] m, estimate}, or null to hide it): the
   * ball at the stage position, its apex height exaggerated like the scan. `markerUm` sizes the
   * marks, `surfaceUnder(x, y)` (µm) is the scan's height below, `addTrail` false redraws the
   * same telemetry (a new exaggeration) without a trail point. False when nothing changed: an
   * idle tip (the same position, 60 times a second) costs no frame.
   */
  set(tip, { markerUm, exaggeration, surfaceUnder, addTrail = true }) {
    const same = tip && this.last && addTrail && tip.stage.every((v, i) => v === this.last.stage[i]) &&
      String(tip.estimate) === String(this.last.estimate);
    if (same) return false;
    this.last = tip;
    if (!tip) {
      this.ball.visible = false;
      this.drop.visible = false;
      this.estimate.visible = false;
      return true;
    }
    const [x, y, z] = tip.stage;
    const r = markerUm * 0.6;
    const xu = x * UM;
    const yu = y * UM;
    const zu = z * UM;
    this.ball.visible = true;
    this.r = r;
    this.ball.scale.setScalar(r);
    this.ball.position.set(xu, yu, zu * exaggeration + r);
    this.shadow.visible = true;
    this.shadow.position.set(xu, yu, surfaceUnder(xu, yu) * exaggeration);
    const d = this.dropGeom.getAttribute('position');
    d.setXYZ(0, xu, yu, zu * exaggeration);
    d.setXYZ(1, xu, yu, surfaceUnder(xu, yu) * exaggeration);
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
    return true;
  }

  /** Keeps the ball at least TIP_MIN_PX on screen (`heightPx` tall), however far the camera is. */
  scaleToScreen(camera, heightPx) {
    if (!this.ball.visible) return;
    const h = Math.max(1, heightPx);
    const dist = camera.position.distanceTo(this.ball.position);
    const perPx = (2 * dist * Math.tan((camera.fov * Math.PI) / 360)) / h;
    const r = Math.max(this.r ?? 0, TIP_MIN_PX * perPx);
    this.ball.scale.setScalar(r);
    this.shadow.scale.setScalar(r * 1.1);
  }

  clearTrail() {
    this.trailLen = 0;
    this.trail.geometry.setDrawRange(0, 0);
  }
}
