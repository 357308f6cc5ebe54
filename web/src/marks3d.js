// The push in the 3D view: the target picked (a ring and a cross), the preview of the push the
// form would send (an arrow), and the commanded push that runs (everyone sees it: the planned
// path of the particle's centre, an arrowhead at its end). Positions in µm; each call updates its
// objects in place. No DOM: runs in Node (tests).
import * as THREE from 'three';

const UM = 1e6; // metres → µm
const TARGET = 0xff4fa3;
const PATH = 0x4fd1ff;

export class PushMarks {
  /**
   * @param {THREE.Object3D} scene where the preview and the path go (drawn above the surface)
   * @param {THREE.Object3D} zGroup the exaggerated group, where the target goes
   */
  constructor(scene, zGroup) {
    this.target = new THREE.Group();
    const tm = new THREE.MeshBasicMaterial({ color: TARGET, side: THREE.DoubleSide });
    this.target.add(new THREE.Mesh(new THREE.RingGeometry(0.7, 1, 40), tm));
    this.target.add(new THREE.Mesh(new THREE.PlaneGeometry(2.6, 0.18), tm));
    this.target.add(new THREE.Mesh(new THREE.PlaneGeometry(0.18, 2.6), tm));
    this.target.visible = false;
    zGroup.add(this.target);
    this.preview = new THREE.ArrowHelper(new THREE.Vector3(1, 0, 0), new THREE.Vector3(), 1, TARGET);
    this.preview.visible = false;
    scene.add(this.preview);
    this.previewArgs = null;
    this.pushPath = new THREE.Group();
    this.pushPath.visible = false;
    scene.add(this.pushPath);
    this.pathPoints = null; // the path shown, [[x, y] µm…], or null
  }

  /** The target at (x, y) µm, `markerUm` across; null hides it. */
  setTarget(xUm, yUm, markerUm) {
    if (xUm === null || xUm === undefined) {
      this.target.visible = false;
    } else {
      this.target.visible = true;
      this.target.position.set(xUm, yUm, 0.02);
      this.target.scale.setScalar(markerUm);
    }
  }

  /**
   * A push preview arrow from `from` ({x, y, z?} µm), `lengthUm` along `deg`, above the surface
   * exaggerated by `exaggeration`; no `from` or no length hides it.
   */
  setPreview(from, deg, lengthUm, markerUm, exaggeration) {
    if (!from || !(lengthUm > 0)) {
      this.preview.visible = false;
      return;
    }
    this.previewArgs = { from, deg, lengthUm };
    const a = (deg * Math.PI) / 180;
    this.preview.setDirection(new THREE.Vector3(Math.cos(a), Math.sin(a), 0));
    const head = Math.min(lengthUm * 0.3, markerUm * 2);
    this.preview.setLength(lengthUm, head, head * 0.6);
    this.preview.visible = true;
    this.setExaggeration(exaggeration);
  }

  /** Lifts the preview's start with the surface's exaggeration (at least 0.05 µm up). */
  setExaggeration(exaggeration) {
    if (!this.previewArgs || !this.preview.visible) return;
    const { from } = this.previewArgs;
    this.preview.position.set(from.x, from.y, Math.max(0.05, (from.z ?? 0) * exaggeration));
  }

  /** The commanded push path (points in m), drawn for everyone; null (or one point) hides it. */
  setPushPath(path, markerUm) {
    while (this.pushPath.children.length) {
      const c = this.pushPath.children.pop();
      c.geometry?.dispose();
    }
    this.pathPoints = path && path.length >= 2 ? path.map(([x, y]) => [x * UM, y * UM]) : null;
    if (!this.pathPoints) {
      this.pushPath.visible = false;
      return;
    }
    const z = Math.max(0.05, markerUm * 0.2);
    const pts = this.pathPoints.map(([x, y]) => new THREE.Vector3(x, y, z));
    const mat = new THREE.LineBasicMaterial({ color: PATH, depthTest: false });
    const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts), mat);
    line.renderOrder = 998;
    this.pushPath.add(line);
    const a = pts[pts.length - 2];
    const b = pts[pts.length - 1];
    const d = new THREE.Vector3().subVectors(b, a);
    const len = d.length();
    if (len > 0) {
      const head = Math.min(len * 0.4, markerUm * 2.5);
      const arrow = new THREE.ArrowHelper(d.normalize(), b.clone().addScaledVector(d, -head), head, PATH, head, head * 0.6);
      arrow.renderOrder = 998;
      this.pushPath.add(arrow);
    }
    this.pushPath.visible = true;
  }
}
