// The Assemble panel: the pattern drawn on the map (sites placed by clicking with "Place sites"
// on, a preset dropped at a point and dragged, each site's fields, removed by its button or a
// key; the tolerance), "Plan" (the server plans and draws the assignment and the paths; nothing
// moves) and "Assemble" (it runs), where the assembly stands (move k of n) and its final report.
// Viewers see the assembly and its report, not the editor. The map shows the assembly the server
// runs or planned while the pattern is as it was sent, else the pattern being drawn.
import { commands } from './wire.js';
import { controlState } from './session.js';
import { PRESETS } from './presets.js';
import { Pattern } from './pattern.js';
import { SiteEditor } from './siteeditor.js';
import { AssemblyLayer, patternView, assemblyView } from './assemblymap.js';
import { progressText, outcomeClass, outcomeText, reportRows, timesText } from './assemblyreport.js';
import { readNumber } from './controls.js';

/** Rows the site list shows; the rest are edited on the map. */
export const LIST_MAX = 50;

/** Why Plan / Assemble cannot go now, or '' when they can. */
export function assembleWhy(state, pattern) {
  const c = controlState(state).assemble;
  if (!c.enabled) return c.why;
  const a = state.assembly;
  if (a && !a.done) return 'An assembly runs: Stop ends it';
  if (state.push || state.phase === 'scanning') return 'The instrument is busy: wait for the push or scan to end';
  if (!pattern.sites.length) return 'Place at least one site: click the map with "Place sites" on, or drop a preset';
  return '';
}

export class AssemblePanel {
  /**
   * @param {(id: string) => HTMLElement} $
   * @param {Document} doc
   * @param {object} deps
   * @param {import('./session.js').Session} deps.session
   * @param {import('./mapoverlay.js').MapOverlay} deps.map
   * @param {(m: object) => object | null} deps.send
   * @param {import('./controls.js').Replies} deps.replies
   * @param {(text: string) => void} deps.announce
   */
  constructor($, doc, { session, map, send, replies, announce }) {
    this.$ = $;
    this.doc = doc;
    this.session = session;
    this.st = session.state;
    this.map = map;
    this.send = send;
    this.replies = replies;
    this.announce = announce;
    this.pattern = new Pattern(this.st.stageRange * 1e6);
    this.sentVersion = null; // the pattern's version when last sent
    this.assemblyVersion = 0; // bumped by every assembly event
    this.listed = -1; // the pattern's version the site list shows
    this.editor = new SiteEditor(this.pattern, {
      say: (text) => {
        this.error('');
        this.announce(text);
      },
      onError: (e) => this.error(e.message),
    });
    map.layer = new AssemblyLayer(map.gAssembly, () => this.mapSource());
    this.bind();
    this.showParams();
  }

  /** What the map draws: the assembly while it runs or the pattern is as sent, else the pattern. */
  mapSource() {
    const a = this.st.assembly;
    const radii = (this.st.particles ?? []).map((p) => p.radius).sort((x, y) => x - y);
    const radiusM = radii.length ? radii[radii.length >> 1] : 0;
    const p = this.pattern;
    if (a && (!a.done || p.version === this.sentVersion || !p.sites.length)) {
      return { view: assemblyView(a), key: `a${a.id}.${this.assemblyVersion}`, radiusM };
    }
    if (!p.sites.length) return null;
    return { view: patternView(p, this.st.pushTolerance?.default), key: `p${p.version}`, radiusM };
  }

  /** The pattern changed: the map and the list follow. */
  changed() {
    this.map.invalidate();
    this.render();
  }

  error(text) {
    const out = this.$('asm-error');
    out.textContent = text;
    out.hidden = !text;
  }

  /** Each preset shows its own parameters only. */
  showParams() {
    const used = PRESETS[this.$('asm-kind').value].params;
    for (const l of this.doc.querySelectorAll('#asm-preset [data-param]')) l.hidden = !used.includes(l.dataset.param);
  }

  params() {
    const ids = { n: 'asm-n', rows: 'asm-rows', cols: 'asm-cols', spacing_um: 'asm-spacing', radius_um: 'asm-radius', angle_deg: 'asm-angle' };
    const out = {};
    for (const [k, id] of Object.entries(ids)) out[k] = readNumber(this.$(id).value);
    return out;
  }

  /** The scene's stage: sites stay on it; a preset is dropped at its centre unless told. */
  applyScene() {
    const r = this.st.stageRange * 1e6;
    this.pattern.rangeUm = r;
    for (const id of ['asm-x', 'asm-y']) this.$(id).max = String(r);
    if (!this.centreTouched) {
      this.$('asm-x').value = String(r / 2);
      this.$('asm-y').value = String(r / 2);
    }
  }

  drop() {
    const kind = this.$('asm-kind').value;
    const at = [readNumber(this.$('asm-x').value), readNumber(this.$('asm-y').value)];
    try {
      if (at.some((v) => v === undefined)) throw new RangeError('the preset needs its centre x and y (µm)');
      const added = this.pattern.drop(kind, this.params(), at);
      this.error('');
      this.announce(`${kind} of ${added.length} sites dropped at (${at[0]}, ${at[1]}) µm; drag it on the map with "Place sites" on`);
    } catch (e) {
      if (!(e instanceof RangeError)) throw e;
      this.error(e.message);
    }
    this.changed();
  }

  /** Plan (nothing moves) or Assemble: the pattern's sites to the server. */
  go(planOnly) {
    const p = this.pattern;
    try {
      p.setTolerance(readNumber(this.$('asm-tol').value));
      const m = commands.assemble({ sites: p.sites, toleranceNm: p.toleranceNm, planOnly }, undefined, { rangeUm: p.rangeUm, tolerance: this.st.pushTolerance });
      this.error('');
      this.sentVersion = p.version;
      this.send(m);
    } catch (e) {
      if (!(e instanceof RangeError)) throw e;
      this.error(`not sent: ${e.message}`);
    }
  }

  setPlacing(on) {
    this.$('asm-place').setAttribute('aria-pressed', String(on));
    this.map.editor = on ? this.editor : null;
    this.announce(on ? 'placing sites: click the map to add one, drag one to move it' : 'placing sites off: the map picks particles and targets again');
  }

  /**
   * An assembly event of the Session (or a state that changed it): redrawn; at its end, the
   * reply of this page's Plan or Assemble says how it ended.
   */
  assemblyChanged(ev) {
    this.assemblyVersion++;
    const a = this.st.assembly;
    if (ev?.what === 'done' && a?.by === this.st.client && this.replies.latest('reply-assemble') !== undefined) {
      const out = this.$('reply-assemble');
      this.replies.show('reply-assemble', outcomeClass(a.done), a.done.outcome === 'planned' ? 'planned' : `ended: ${outcomeText(a.done).split(/[:(]/)[0].trim().toLowerCase()}`, out.title);
    }
    this.map.invalidate();
    this.render();
  }

  /** Enables what may be done now; the progress, the report and the site list. */
  render() {
    const { $, st } = this;
    const viewer = st.role === 'viewer';
    $('asm-fs').hidden = viewer;
    $('asm-plan').hidden = viewer;
    $('asm-run').hidden = viewer;
    const why = assembleWhy(st, this.pattern);
    for (const id of ['asm-plan', 'asm-run']) {
      $(id).disabled = !!why;
      $(id).title = why;
    }
    $('asm-why').textContent = viewer ? '' : why;
    const a = st.assembly;
    const running = !!(a && !a.done);
    $('asm-fs').disabled = running;
    if (running && this.map.editor) this.setPlacing(false);
    const prog = $('asm-progress');
    // While disconnected the line is what was last known, and says so.
    const away = st.connection !== 'open' && a && !a.done;
    prog.textContent = a ? `${away ? 'Last known, while disconnected: ' : ''}${progressText(a)}` : '';
    prog.className = `lastrun ${a?.done ? outcomeClass(a.done) : 'neutral'}`;
    // Once the report is there it says the outcome: the line would say it twice.
    prog.hidden = !a || !!a.done?.summary;
    this.renderReport(a);
    if (this.listed !== this.pattern.version) this.renderList();
  }

  renderReport(a) {
    const { $ } = this;
    const sum = a?.done?.summary;
    $('asm-report').hidden = !sum;
    // Built once per assembly event: the page renders on every message.
    if (!sum || this.reported === this.assemblyVersion) return;
    this.reported = this.assemblyVersion;
    const d = a.done;
    $('asm-outcome').textContent = `${outcomeText(d)}${d.record ? ` · record ${d.record}` : d.record_error ? ` · no record: ${d.record_error}` : ''}`;
    $('asm-outcome').className = `lastrun ${outcomeClass(d)}`;
    $('asm-times').textContent = timesText(sum);
    $('asm-rows').replaceChildren(...reportRows(sum).map((r) => {
      const tr = this.doc.createElement('tr');
      tr.className = r.cls;
      for (const v of [r.site, r.at, r.state, r.particle, r.error, r.reason]) {
        const td = this.doc.createElement('td');
        td.textContent = String(v);
        tr.append(td);
      }
      return tr;
    }));
  }

  /** The site list: each site's fields and its Remove button (the first LIST_MAX). */
  renderList() {
    const { doc, pattern: p } = this;
    this.listed = p.version;
    const n = p.sites.length;
    const more = n > LIST_MAX ? ` (the first ${LIST_MAX} listed; edit the others on the map)` : '';
    const count = `${n} site${n === 1 ? '' : 's'}`;
    const name = p.name();
    this.$('asm-count').textContent = n ? `${name === count ? count : `${count}: ${name}`}${more}` : 'No sites yet';
    // A field being typed in keeps its focus (and its text) across a redraw of the list.
    const focused = doc.activeElement?.closest?.('#asm-sites') ? doc.activeElement.id : null;
    const rows = p.sites.slice(0, LIST_MAX).map((s, i) => {
      const tr = doc.createElement('tr');
      if (s.id === p.selected) tr.className = 'selected';
      const th = doc.createElement('th');
      th.scope = 'row';
      th.textContent = String(i + 1);
      tr.append(th);
      for (const k of ['x_um', 'y_um']) {
        const td = doc.createElement('td');
        const input = doc.createElement('input');
        Object.assign(input, { type: 'number', step: 'any', min: '0', max: String(p.rangeUm), value: s[k].toFixed(2), id: `asm-site-${s.id}-${k}` });
        input.setAttribute('aria-label', `site ${i + 1} ${k[0]} (µm)`);
        input.addEventListener('change', () => this.placeFromList(s.id));
        input.addEventListener('focus', () => this.select(s.id));
        td.append(input);
        tr.append(td);
      }
      const td = doc.createElement('td');
      const b = doc.createElement('button');
      Object.assign(b, { type: 'button', className: 'small', textContent: 'Remove', id: `asm-site-${s.id}-rm` });
      b.setAttribute('aria-label', `Remove site ${i + 1}`);
      b.addEventListener('click', () => this.removeSite(s.id));
      td.append(b);
      tr.append(td);
      return tr;
    });
    this.$('asm-sites').replaceChildren(...rows);
    if (focused) doc.getElementById(focused)?.focus();
  }

  select(id) {
    if (this.pattern.selected === id) return;
    this.pattern.selected = id;
    this.pattern.changed();
    this.map.invalidate();
  }

  placeFromList(id) {
    const x = readNumber(this.$(`asm-site-${id}-x_um`).value);
    const y = readNumber(this.$(`asm-site-${id}-y_um`).value);
    try {
      this.pattern.place(id, x ?? Number.NaN, y ?? Number.NaN);
      this.error('');
    } catch (e) {
      if (!(e instanceof RangeError)) throw e;
      this.error(e.message);
      this.listed = -1; // the fields back to where the site is
    }
    this.changed();
  }

  removeSite(id) {
    const n = this.pattern.number(id);
    this.pattern.remove(id);
    this.announce(`site ${n} removed; ${this.pattern.sites.length} left`);
    this.changed();
    // The focus to the next site's Remove button, else the list's neighbour, else Clear.
    const next = this.pattern.selected;
    (next !== null && this.$(`asm-site-${next}-rm`)) ? this.$(`asm-site-${next}-rm`).focus() : this.$('asm-clear').focus();
  }

  bind() {
    const { $ } = this;
    $('asm-kind').addEventListener('change', () => this.showParams());
    $('asm-drop').addEventListener('click', () => this.drop());
    $('asm-place').addEventListener('click', () => this.setPlacing($('asm-place').getAttribute('aria-pressed') !== 'true'));
    $('asm-clear').addEventListener('click', () => {
      this.pattern.clear();
      this.error('');
      this.announce('all sites cleared');
      this.changed();
    });
    for (const id of ['asm-x', 'asm-y']) $(id).addEventListener('input', () => { this.centreTouched = true; });
    $('asm-tol').addEventListener('change', () => {
      try {
        this.pattern.setTolerance(readNumber($('asm-tol').value));
        this.error('');
      } catch (e) {
        if (!(e instanceof RangeError)) throw e;
        this.error(e.message);
      }
      this.changed();
    });
    $('asm-plan').addEventListener('click', () => this.go(true));
    $('asm-run').addEventListener('click', () => this.go(false));
    // Every change the map's gestures make reaches the list.
    this.map.svg.addEventListener('pointerup', () => this.render());
    this.map.svg.addEventListener('keyup', () => this.render());
  }
}
