// The 3D view's toolbar: frame the stage, the scan or the tip, clear the trail, and the height
// exaggeration (a logarithmic slider, 1-1000×, and "Auto": heights scaled to 15 % of the scan
// width, applied again after each scan until the operator moves the slider). The exaggeration's
// numbers are pure (Node tests).

/** An exaggeration within the slider's 1-1000×. */
export function clampExaggeration(x) {
  return Math.min(1000, Math.max(1, x));
}

/** The slider's readout: one decimal below 10×. */
export function exaggerationLabel(v) {
  return v < 10 ? v.toFixed(1) : v.toFixed(0);
}

/** "Auto": the exaggeration that makes the scan's height range 15 % of its shorter side; null
 * for no scan or a flat one. */
export function autoExaggerationFor(sc) {
  if (!sc || !(sc.max > sc.min)) return null;
  const side = Math.min(sc.x_real, sc.y_real);
  const auto = (0.15 * side) / (sc.max - sc.min);
  // The tallest feature at most 8 pixel widths high: a sub-pixel particle is not a pillar.
  if (!(sc.xres > 0 && sc.yres > 0)) return auto;
  const px = Math.min(sc.x_real / sc.xres, sc.y_real / sc.yres);
  return Math.min(auto, (8 * px) / (sc.max - sc.min));
}

export class Toolbar {
  /**
   * @param {(id: string) => HTMLElement} $ the page's elements by id
   * @param {import('./view3d.js').View3D} view
   * @param {() => object | null} liveScan the Session's scan (what "Auto" scales to)
   */
  constructor($, view, liveScan) {
    this.$ = $;
    this.view = view;
    this.liveScan = liveScan;
    this.exagTouched = false; // the operator moved the slider: no more automatic exaggeration
    $('exag').addEventListener('input', () => {
      this.exagTouched = true;
      this.setExaggeration(10 ** Number($('exag').value));
    });
    $('exag-auto').addEventListener('click', () => {
      this.exagTouched = false;
      this.autoExaggeration();
    });
    $('frame-stage').addEventListener('click', () => view.frameStage());
    $('frame-scan').addEventListener('click', () => view.frameScan());
    $('frame-tip').addEventListener('click', () => view.frameTip());
    $('clear-trail').addEventListener('click', () => view.clearTrail());
  }

  setExaggeration(x) {
    const v = clampExaggeration(x);
    this.$('exag').value = String(Math.log10(v));
    this.$('exag-val').textContent = exaggerationLabel(v);
    this.view.setExaggeration(v);
  }

  autoExaggeration() {
    const x = autoExaggerationFor(this.liveScan());
    if (x !== null) this.setExaggeration(x);
  }

  /** A scan filled: "Auto" again, unless the operator chose an exaggeration. */
  scanFilled() {
    if (!this.exagTouched) this.autoExaggeration();
  }
}
