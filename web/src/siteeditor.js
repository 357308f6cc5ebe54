// The pattern's gestures on the map, no DOM: with "Place sites" on, a click on an empty spot
// adds a site, a press on a site selects it and a drag moves it (a dropped preset as a whole,
// the site kept under the pointer); by keyboard at the map's cursor, Enter (or Space) selects
// the site under it or adds one there, `m` moves the selected site (and its preset) to the
// cursor, Delete or Backspace removes the selected site. Points are stage µm, as the map has
// them; `hitUm` is a site ring's radius on screen, in µm. Each change is said in words
// (`say`); a refusal (off the stage, too many sites) is given to `onError`. Runs in Node (tests).
import { formatPoint } from './format.js';

const at = (s) => formatPoint([s.x_um * 1e-6, s.y_um * 1e-6]);

export class SiteEditor {
  /**
   * @param {import('./pattern.js').Pattern} pattern
   * @param {{say?: (text: string) => void, onError?: (e: Error) => void}} [hooks]
   */
  constructor(pattern, { say = () => {}, onError = () => {} } = {}) {
    this.pattern = pattern;
    this.say = say;
    this.onError = onError;
    this.drag = null; // {id, offset: [dx, dy] µm from the pointer to the site, moved}
  }

  /** Tries `f`; a RangeError (a refusal in words) goes to onError. */
  guard(f) {
    try {
      return f();
    } catch (e) {
      if (!(e instanceof RangeError)) throw e;
      this.onError(e);
      return null;
    }
  }

  /** A press at (x, y) µm: on a site, selects it and starts its drag (true); else false. */
  down(xUm, yUm, hitUm) {
    const s = this.pattern.siteAt(xUm, yUm, hitUm);
    if (!s) return false;
    this.pattern.selected = s.id;
    this.pattern.changed();
    this.drag = { id: s.id, offset: [s.x_um - xUm, s.y_um - yUm], moved: false };
    return true;
  }

  /** The pointer moved while a site is dragged: it follows (true); false when none is. */
  move(xUm, yUm) {
    const d = this.drag;
    if (!d) return false;
    const s = this.pattern.site(d.id);
    const [dx, dy] = this.pattern.moveBy(d.id, xUm + d.offset[0] - s.x_um, yUm + d.offset[1] - s.y_um);
    if (dx || dy) d.moved = true;
    return true;
  }

  /**
   * The press ended at (x, y) µm (null off the map); `click`: it did not travel. The end of a
   * drag, or a click that adds a site on an empty spot: true; false when it was neither.
   */
  up(xUm, yUm, click) {
    const d = this.drag;
    this.drag = null;
    if (d) {
      const s = this.pattern.site(d.id);
      const n = this.pattern.number(d.id);
      if (d.moved) this.say(s.group === null ? `site ${n} moved to ${at(s)}` : `pattern moved: site ${n} now at ${at(s)}`);
      else this.say(`site ${n} selected, at ${at(s)}`);
      return true;
    }
    if (!click || xUm === null) return false;
    return this.add(xUm, yUm);
  }

  add(xUm, yUm) {
    const s = this.guard(() => this.pattern.add(xUm, yUm));
    if (s) this.say(`site ${this.pattern.number(s.id)} added at ${at(s)}`);
    return true;
  }

  /** A key on the map with its cursor at `cursorUm`: true when it was the editor's. */
  key(key, cursorUm, hitUm) {
    const p = this.pattern;
    const sel = p.selected === null ? null : p.site(p.selected);
    if (key === 'Enter' || key === ' ') {
      const s = p.siteAt(cursorUm[0], cursorUm[1], hitUm);
      if (!s) return this.add(cursorUm[0], cursorUm[1]);
      p.selected = s.id;
      p.changed();
      this.say(`site ${p.number(s.id)} selected, at ${at(s)}`);
      return true;
    }
    if (key === 'Delete' || key === 'Backspace') {
      if (!sel) {
        this.say('no site selected to remove');
        return true;
      }
      const n = p.number(sel.id);
      p.remove(sel.id);
      this.say(`site ${n} removed; ${p.sites.length} left`);
      return true;
    }
    if (key === 'm') {
      if (!sel) {
        this.say('no site selected to move');
        return true;
      }
      p.moveBy(sel.id, cursorUm[0] - sel.x_um, cursorUm[1] - sel.y_um);
      this.say(`${sel.group === null ? `site ${p.number(sel.id)}` : 'pattern'} moved: site ${p.number(sel.id)} now at ${at(sel)}`);
      return true;
    }
    return false;
  }
}
