// The particles in the 3D view: translucent spheres, each labelled with its id beside it (a
// CSS2D label: it never covers the sphere, where the tip works), the selected one highlighted;
// shown at least stage/250 across so tiny ones stay visible. `shownRadiusUm` and `particleTitle`
// are pure (Node tests).
import * as THREE from 'three';
import { CSS2DObject } from 'three/addons/renderers/CSS2DRenderer.js';
import { formatLength } from './format.js';

const UM = 1e6; // metres → µm
const COLOUR = 0xe6c35c;
const SELECTED = 0xffe08a;

/** The radius (µm) a particle of `radiusM` is drawn with on a stage `stageUm` wide. */
export function shownRadiusUm(radiusM, stageUm) {
  return Math.max(radiusM * UM, stageUm / 250);
}

/** A particle's label's tooltip: its id, material and radius. */
export function particleTitle(p) {
  return `particle ${p.id}${p.material ? ` (${p.material})` : ''}, radius ${formatLength(p.radius)}`;
}

export class ParticleSpheres {
  /** @param {THREE.Object3D} parent the group the spheres are added to */
  constructor(parent) {
    this.group = new THREE.Group();
    parent.add(this.group);
    this.meshes = new Map(); // id → sphere
  }

  /** The scene's particles (metres: {id, radius, x, y, material}), replacing those shown. */
  set(particles, selectedId, stageUm, overScan) {
    for (const m of this.meshes.values()) {
      this.group.remove(m);
      m.traverse((o) => o.isCSS2DObject && o.element.remove());
    }
    this.meshes.clear();
    for (const p of particles) {
      const rUm = p.radius * UM;
      const shown = shownRadiusUm(p.radius, stageUm);
      const mesh = new THREE.Mesh(
        new THREE.SphereGeometry(1, 32, 20),
        new THREE.MeshBasicMaterial({ color: COLOUR, transparent: true, opacity: 0.45, depthWrite: false }),
      );
      mesh.scale.setScalar(shown);
      mesh.userData = { id: p.id, rUm, shown };
      const el = document.createElement('div');
      el.className = 'plabel';
      el.textContent = `#${p.id}`;
      el.title = particleTitle(p);
      const label = new CSS2DObject(el);
      // Beside the sphere, not over it (where the tip works), and see-through.
      label.position.set(1.15, 0, 0);
      label.center.set(0, 0.5);
      mesh.add(label);
      this.group.add(mesh);
      this.meshes.set(p.id, mesh);
    }
    this.update(particles, selectedId, overScan);
  }

  /**
   * Moves the spheres to the particles' positions and highlights the selected one; `overScan`
   * (a scan is shown) makes them fainter, so the surface shows through.
   */
  update(particles, selectedId, overScan) {
    for (const p of particles) {
      const m = this.meshes.get(p.id);
      if (!m) continue;
      m.position.set(p.x * UM, p.y * UM, m.userData.rUm);
      const sel = p.id === selectedId;
      m.material.color.set(sel ? SELECTED : COLOUR);
      m.material.opacity = (sel ? 0.6 : 0.4) * (overScan ? 0.5 : 1);
      m.children[0].element.classList.toggle('selected', sel);
    }
  }

  /** A particle's centre (µm), or null for one not shown. */
  centre(id) {
    const m = this.meshes.get(id);
    return m ? m.position : null;
  }
}
