// Which scan the views show: the Session's live scan (filled line by line, or fetched whole from
// its record for a late joiner) or a past scan opened from the records (shown until the next
// live scan starts); the 3D legend (colour scale, progress, stale) and the image's title.
// `progressText` and `scanTitle` are pure (Node tests).
import { apiUrl } from './connection.js';
import { parseGsf } from './gsf.js';
import { Session } from './session.js';
import { formatLength } from './format.js';
import { viridisCss } from './colormap.js';
import { scanSize, scanDoneNote } from './eventlog.js';

/** The legend's progress line for the live scan. */
export function progressText(sc, stale) {
  const what = sc.done ? `scan ${sc.id} complete` : sc.interrupted ? `scan ${sc.id} interrupted at line ${sc.lines}/${sc.yres}` : `scan ${sc.id}: line ${sc.lines}/${sc.yres}`;
  // A scan from before a restart is stale whatever ran since: the new server's sample is the scene's.
  return what + (sc.previousRun ? ' · from before the server restarted' : stale ? ' · stale (a push ran since)' : '');
}

/** The height image's title: the record opened, else the live scan's id. */
export function scanTitle(openedRecord, sc) {
  return openedRecord ? `· record ${openedRecord}` : `· scan ${sc.id}`;
}

export class Scans {
  /**
   * @param {(id: string) => HTMLElement} $ the page's elements by id
   * @param {object} deps
   * @param {Session} deps.session
   * @param {import('./view3d.js').View3D} deps.view
   * @param {import('./image2d.js').Image2D} deps.image2d
   * @param {import('./eventlog.js').EventLog} deps.log
   * @param {import('./toolbar.js').Toolbar} deps.toolbar
   * @param {Location} deps.loc
   * @param {() => number | null} deps.selected the selected particle
   * @param {() => void} deps.markLegend redraw the legend in the next frame
   */
  constructor($, { session, view, image2d, map = null, log, toolbar, loc, selected, markLegend }) {
    this.map = map;
    this.$ = $;
    this.session = session;
    this.st = session.state;
    this.view = view;
    this.image2d = image2d;
    this.log = log;
    this.toolbar = toolbar;
    this.loc = loc;
    this.selected = selected;
    this.markLegend = markLegend;
    this.openedRecord = null; // a past scan opened from the records (not the live one)
    this.framed = false; // the camera went to the scan since the operator asked for it
    $('legend-bar').style.background = `linear-gradient(to right, ${viridisCss()})`;
  }

  /** The operator asked for a scan: frame it once it starts. */
  requested() {
    this.framed = false;
  }

  /** `scan_start`: the new scan replaces whatever was shown. */
  started() {
    const st = this.st;
    this.openedRecord = null;
    this.map?.setScanParticles([]);
    this.show();
    this.log.log(`scan ${st.scan.id} started: ${scanSize(st.scan)}`);
    this.frameOnce();
  }

  /** A scan line arrived (`ev` from the Session). */
  line(ev) {
    if (this.openedRecord) return; // a past scan is shown; the live one fills the Session only
    this.view.scanLine(this.st.scan, ev.line);
    this.image2d.invalidate();
    this.markLegend();
  }

  /**
   * `scan_done`. A page that missed lines (it joined mid-scan, or lagged) fetches the whole scan
   * from its record, so what it shows is the scan, not part of it.
   */
  done(ev) {
    const n = scanDoneNote(ev);
    this.log.log(n.text, n.cls);
    this.toolbar.scanFilled();
    this.renderLegend();
    const sc = this.st.scan;
    if (sc && ev.record && !this.openedRecord) {
      if (sc.lines < sc.yres) {
        this.log.log(`scan ${sc.id}: ${sc.yres - sc.lines} of ${sc.yres} lines were not seen here; loading the whole scan from ${ev.record}`);
        this.loadLatest(sc.id, ev.record);
      }
      this.loadFound(ev.record);
    }
  }

  /** The particles a scan found (its record's JSON summary beside the GSF) onto the map. */
  async loadFound(gsfName) {
    if (!this.map) return;
    try {
      const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(gsfName.replace(/\.gsf$/, '.json'))}`, this.loc));
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      const j = await r.json();
      this.map.setScanParticles(j.particles ?? []);
    } catch {
      this.map.setScanParticles([]);
    }
  }

  /** The server's `state`: a scan other than the one shown is the latest; fetch it if done. */
  stateChanged(ev) {
    const st = this.st;
    if (ev.scanFinished && !this.openedRecord) {
      // It ended while this page was away: the lines missed come from its record.
      this.toolbar.scanFilled();
      if (st.scan.record) {
        if (st.scan.lines < st.scan.yres) this.loadLatest(st.scan.id, st.scan.record);
        this.loadFound(st.scan.record);
      }
    }
    if (ev.scanChanged && !this.openedRecord) {
      this.show();
      this.map?.setScanParticles([]);
      if (st.scan.done && st.scan.record) {
        this.loadLatest(st.scan.id, st.scan.record);
        this.loadFound(st.scan.record);
      }
    }
  }

  frameOnce() {
    if (!this.framed) {
      this.view.frameScan();
      this.framed = true;
    }
  }

  /** Shows the Session's scan (new, or refilled) in both views. */
  show() {
    const { st, view, $ } = this;
    view.startScan(st.scan);
    if (st.scan.lines) view.fillScan(st.scan);
    this.image2d.setScan(st.scan);
    $('legend').hidden = false;
    $('img-title').textContent = scanTitle(this.openedRecord, st.scan);
    view.updateParticles(st.particles, this.selected());
    this.renderStale();
    this.renderLegend();
  }

  /** A late joiner's latest scan: its heights from the record the server names. */
  async loadLatest(id, record) {
    try {
      const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(record)}`, this.loc));
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      const g = parseGsf(await r.arrayBuffer());
      if (!this.session.fillScan(id, g.heights)) return; // another scan started meanwhile
      this.view.fillScan(this.st.scan);
      this.image2d.invalidate();
      this.toolbar.scanFilled();
      this.frameOnce();
      this.renderLegend();
    } catch (e) {
      this.log.log(`could not load the latest scan ${record}: ${e.message}`, 'bad');
    }
  }

  /** A past scan from the records, shown until the next live scan starts. */
  async openRecord(name) {
    const { view, $ } = this;
    try {
      const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(name)}`, this.loc));
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      const g = parseGsf(await r.arrayBuffer());
      const s = new Session();
      s.startScan({ scan: -1, xres: g.xres, yres: g.yres, x_offset: g.x_offset, y_offset: g.y_offset, x_real: g.x_real, y_real: g.y_real });
      s.fillScan(-1, g.heights);
      this.openedRecord = name;
      const sc = s.state.scan;
      view.startScan(sc);
      view.fillScan(sc);
      this.image2d.setScan(sc);
      $('img-title').textContent = scanTitle(name, sc);
      $('img-stale').hidden = true;
      this.loadFound(name);
      view.frameScan();
      this.log.log(`opened ${name}: ${scanSize(g)}`);
    } catch (e) {
      this.log.log(`could not open ${name}: ${e.message}`, 'bad');
    }
  }

  /**
   * An assembly's end: the last full frame it judged its sites by (its record names it), shown
   * as an opened record. The server takes that frame without streaming it, so a page that
   * watched the assembly would otherwise keep the scan from before it.
   */
  async openAssemblyFrame(assemblyRecord) {
    try {
      const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(assemblyRecord)}`, this.loc));
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      const name = (await r.json())?.final_frame?.record;
      if (typeof name === 'string' && name) await this.openRecord(name);
    } catch (e) {
      this.log.log(`could not load the assembly's last full frame from ${assemblyRecord}: ${e.message}`, 'bad');
    }
  }

  /** The "stale: a push ran since this scan" marks (the live scan only). */
  renderStale() {
    const st = this.st;
    const stale = st.scanStale && !this.openedRecord && !!st.scan;
    this.$('img-stale').hidden = !stale;
    this.$('img-stale').textContent = st.scan?.previousRun ? 'stale: from before the server restarted' : 'stale: a push ran since this scan';
    this.$('scan-progress').classList.toggle('stale', stale);
    this.markLegend();
  }

  /** The 3D legend: the colour scale in use and the live scan's progress. */
  renderLegend() {
    const { st, $ } = this;
    const sc = st.scan;
    if (!sc) return;
    const r = this.view.colourScale();
    if (r) {
      $('legend-lo').textContent = formatLength(r.lo);
      $('legend-hi').textContent = formatLength(r.hi);
    }
    $('scan-progress').textContent = progressText(sc, st.scanStale);
  }
}
