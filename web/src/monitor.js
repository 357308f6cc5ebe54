// The monitoring view (`/?view=monitor`), for a wall screen: read-only, big, calm. A thumbnail
// of the latest scan with the particles (where the controller believes they are), the tip and
// the phase; the instrument's phase, the control loop's health, the haptic link and its
// device's faults (`deviceFaultsLine`, src/devicefaults.js), clients, the lease, and the alerts
// a lab pages on (from /api/status, every second); the run history from the records on disk
// (/api/runs, so it survives restarts and a monitor opened late). While the server does not
// answer, the page says so at the top in words ("server down since 14:02:11") and greys every
// tile: nothing old is shown as if it were live. A viewer WebSocket (streams `tip` and `scan`)
// keeps the thumbnail live. One column on a phone, up to four tiles a row on a 4K screen.
// `statusTiles`, `alertsOf`, `runLine` and `downText` are pure (Node tests); `start()`
// (src/main.js) builds the page.
import { Session, describeRun, runClass } from './session.js';
import { wsUrl, apiUrl, backoffMs } from './connection.js';
import { commands } from './wire.js';
import { deviceFaultsLine } from './devicefaults.js';
import { clockTime } from './eventlog.js';
import { viridisTable } from './colormap.js';
import { level } from './heightmap.js';
import { phaseWords } from './words.js';

const POLL_MS = 1000;
const RUNS_MS = 5000;
/** A request unanswered this long means the server is down (hung, or cut off without a close). */
const ANSWER_MS = 3000;

/** GET within `ANSWER_MS`; a late answer is an error that says so. */
async function get(path) {
  try {
    const r = await fetch(apiUrl(path, location), { signal: AbortSignal.timeout(ANSWER_MS) });
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    return await r.json();
  } catch (e) {
    if (e?.name === 'TimeoutError') throw new Error(`no answer within ${ANSWER_MS / 1000} s`);
    throw e;
  }
}

function h(tag, attrs = {}, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  e.append(...kids);
  return e;
}

function build() {
  document.title = 'Monitor · Nano Visulator · nanopush';
  document.body.className = 'monitor';
  const tile = (id, label, cls = 'tile') => h('div', { class: cls }, h('dt', {}, label), h('dd', { id }, '–'));
  const main = h('main', { class: 'mon' },
    h('h1', {}, 'nanopush monitor ', h('span', { class: 'sub', id: 'm-scene' }, '')),
    h('p', { id: 'm-conn', class: 'm-conn', role: 'status' }, 'connecting…'),
    h('div', { class: 'mon-grid' },
      h('figure', { class: 'm-thumb live' },
        h('canvas', { id: 'm-canvas', width: 480, height: 480, role: 'img', 'aria-label': 'The latest scan: no scan yet' }),
        h('figcaption', { id: 'm-thumb-cap' }, 'no scan yet')),
      h('dl', { class: 'tiles live' },
        tile('m-phase', 'Instrument phase'),
        tile('m-alerts', 'Alerts'),
        tile('m-loop', 'Control loop'),
        tile('m-jitter', 'Period error p99'),
        tile('m-haptic', 'Haptic link'),
        tile('m-clients', 'Clients'),
        tile('m-lease', 'Lease'),
        tile('m-uptime', 'Up since'),
        tile('m-hapdev', 'Haptic device', 'tile wide'))),
    h('section', { 'aria-labelledby': 'm-runs-h' },
      h('h2', { id: 'm-runs-h' }, 'Run history ', h('span', { class: 'sub' }, '(from the records on disk)')),
      h('ol', { id: 'm-runs', class: 'm-runs' }, h('li', {}, 'loading…'))));
  document.body.replaceChildren(main);
}

/** Writes a tile (or the banner): its text, and its state class beside the classes it was built with. */
function set(id, text, cls = '') {
  const e = document.getElementById(id);
  e.textContent = text;
  e.dataset.base ??= e.className;
  e.className = [e.dataset.base, cls].filter(Boolean).join(' ');
}

/** The alerts a lab pages on, from an /api/status document: [] when healthy. */
export function alertsOf(s) {
  const out = [];
  const l = s.loop ?? {};
  const hp = s.haptic ?? {};
  if (l.overruns > 0) out.push(`${l.overruns} loop overruns`);
  if (hp.link === 'down' && hp.engaged) out.push('haptic link down while engaged');
  else if (hp.link === 'down') out.push('haptic link down');
  if (hp.fault) out.push(`haptic fault: ${hp.fault}`);
  if (s.dropped_frames > 0) out.push(`${s.dropped_frames} telemetry frames dropped`);
  return out;
}

/**
 * The tiles for an /api/status document, in the order they are written: [element id, text,
 * class] each.
 */
export function statusTiles(s) {
  const l = s.loop ?? {};
  const health = l.overruns > 0 ? `${l.ticks} ticks, ${l.overruns} overruns` : `${l.ticks} ticks, no overruns`;
  const p99 = l.period_error_p99_bound_s;
  const hp = s.haptic ?? {};
  const dev = deviceFaultsLine(s.haptic);
  const alerts = alertsOf(s);
  const downs = Number.isFinite(hp.link_downs) && hp.link_downs > 0 ? `, ${hp.link_downs} link loss${hp.link_downs === 1 ? '' : 'es'}` : '';
  const since = Number.isFinite(s.started_unix_ms) ? `${clockTime(s.started_unix_ms)} (${Math.floor(s.uptime_s / 60)} min)` : `${Math.floor(s.uptime_s / 60)} min ${Math.floor(s.uptime_s % 60)} s`;
  return [
    ['m-scene', `· ${s.scene}`, ''],
    ['m-phase', phaseWords(s.phase) + (s.busy ? ' (busy)' : ''), ''],
    ['m-alerts', alerts.length ? alerts.join('; ') : 'none', alerts.length ? 'bad' : 'good'],
    ['m-loop', `${health}${l.realtime ? ', real-time' : ', not real-time'}`, l.overruns > 0 ? 'warn' : 'good'],
    ['m-jitter', Number.isFinite(p99) ? (p99 < 1e-3 ? `≤ ${(p99 * 1e6).toFixed(0)} µs` : `≤ ${(p99 * 1e3).toPrecision(3)} ms`) : '–', p99 > 1e-3 ? 'warn' : ''],
    ['m-haptic', (hp.link === 'off' || !hp.link ? 'off' : `${hp.link}${hp.engaged ? ', engaged' : ''}`) + downs, hp.link === 'down' ? 'bad' : ''],
    ['m-clients', String(s.clients), ''],
    ['m-lease', s.lease === null ? 'free' : s.lease_name ? `${s.lease_name} (client ${s.lease})` : `client ${s.lease}`, ''],
    ['m-uptime', since, ''],
    ['m-hapdev', dev.text, dev.cls],
  ];
}

/**
 * Why a request to the server failed, in words: the browser's "Failed to fetch" (and its
 * cousins) mean the server cannot be reached; an HTTP status or a time-out says itself.
 */
export function whyDown(message) {
  return /failed to fetch|networkerror|load failed|network request failed/i.test(String(message)) ? 'it cannot be reached' : String(message);
}

/** The banner while the server does not answer: since when (Unix ms), and the last error. */
export function downText(sinceMs, why) {
  return `server down since ${clockTime(sinceMs)} (${whyDown(why)}); what is shown below is from before`;
}

/** One line of the run history (an /api/runs entry): its time, what it was, and who ran it. */
export function runLine(r) {
  return `${clockTime(r.modified * 1000)} ${describeRun({ ...r, record: r.record })}${r.person ? ` — ${r.person}` : ''}`;
}

const LUT = viridisTable(256);

class Monitor {
  constructor() {
    this.session = new Session();
    this.downSince = null;
    this.instance = null;
    this.note = null; // a restart or an outage this screen saw
    this.drawn = -1;
    this.polling = false; // a status request is out
    this.dirty = false;
  }

  async poll() {
    if (this.polling) return; // one at a time: a hung server would pile them up
    this.polling = true;
    try {
      const s = await get('/api/status');
      for (const [id, text, cls] of statusTiles(s)) set(id, text, cls);
      this.status = s;
      const restarted = this.instance !== null && s.instance !== this.instance;
      this.instance = s.instance;
      const back = this.downSince !== null;
      // What this screen saw happen stays said (a wall screen is read now and then).
      if (restarted) this.note = `the server restarted at ${clockTime(s.started_unix_ms)}`;
      else if (back) this.note = `the server was unreachable from ${clockTime(this.downSince)} to ${clockTime(Date.now())}`;
      this.downSince = null;
      document.body.classList.remove('offline');
      set('m-conn', this.note ? `live · ${this.note}` : 'live', 'good');
      if (restarted || back) this.runs();
      this.dirty = true;
    } catch (e) {
      if (this.downSince === null) this.downSince = Date.now();
      document.body.classList.add('offline');
      set('m-conn', downText(this.downSince, e.message), 'down');
    } finally {
      this.polling = false;
    }
  }

  async runs() {
    const ol = document.getElementById('m-runs');
    try {
      const list = await get('/api/runs');
      ol.replaceChildren(...(list.length ? list.slice(0, 12).map((x) => h('li', { class: runClass(x) }, runLine(x))) : [h('li', {}, 'no pushes recorded yet')]));
    } catch {
      // (the banner says the server is down; the list stays as it was, greyed)
    }
  }

  connect(attempt = 0) {
    const session = new Session();
    this.session = session;
    let ws;
    try {
      ws = new WebSocket(wsUrl(location));
    } catch {
      setTimeout(() => this.connect(attempt + 1), backoffMs(attempt + 1));
      return;
    }
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => {
      attempt = 0;
    };
    ws.onmessage = (ev) => {
      const e = session.apply(ev.data);
      if (e.kind === 'welcome') ws.send(JSON.stringify(commands.subscribe(['tip', 'scan'], 1)));
      if (e.kind === 'state' && session.state.scan?.done && session.state.scan.record) this.fetchScan(session.state.scan.id, session.state.scan.record);
      if (e.kind === 'scan_done' && e.record && session.state.scan && session.state.scan.lines < session.state.scan.yres) this.fetchScan(session.state.scan.id, e.record);
      if (e.kind === 'run_done') this.runs();
      this.dirty = true;
    };
    ws.onclose = () => setTimeout(() => this.connect(attempt + 1), backoffMs(attempt + 1));
  }

  async fetchScan(id, record) {
    try {
      const { parseGsf } = await import('./gsf.js');
      const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(record)}`, location));
      if (!r.ok) return;
      const g = parseGsf(await r.arrayBuffer());
      this.session.fillScan(id, g.heights);
      this.dirty = true;
    } catch {
      // (the thumbnail shows what arrived)
    }
  }

  /** The thumbnail: the scan levelled, the particles, the tip; at most a few times a second. */
  draw() {
    if (!this.dirty) return;
    this.dirty = false;
    const st = this.session.state;
    const sc = st.scan;
    const cv = document.getElementById('m-canvas');
    const ctx = cv.getContext('2d');
    const W = cv.width;
    ctx.fillStyle = '#10141a';
    ctx.fillRect(0, 0, W, W);
    const cap = document.getElementById('m-thumb-cap');
    const phase = phaseWords(st.phase ?? this.status?.phase);
    if (!sc) {
      cap.textContent = `no scan yet · phase ${phase}`;
      return;
    }
    if (this.drawn !== sc.version) {
      const lv = level(sc, 'plane');
      let lo = Infinity;
      let hi = -Infinity;
      for (const v of lv) if (Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      const off = document.createElement('canvas');
      off.width = sc.xres;
      off.height = sc.yres;
      const o = off.getContext('2d');
      const img = o.createImageData(sc.xres, sc.yres);
      for (let j = 0; j < sc.yres; j++) {
        for (let i = 0; i < sc.xres; i++) {
          const v = lv[j * sc.xres + i];
          const d = 4 * ((sc.yres - 1 - j) * sc.xres + i);
          if (!Number.isFinite(v)) continue;
          const k = Math.max(0, Math.min(255, Math.round(((v - lo) / (hi - lo || 1)) * 255)));
          img.data[d] = LUT[3 * k] * 255;
          img.data[d + 1] = LUT[3 * k + 1] * 255;
          img.data[d + 2] = LUT[3 * k + 2] * 255;
          img.data[d + 3] = 255;
        }
      }
      o.putImageData(img, 0, 0);
      this.off = off;
      this.drawn = sc.version;
    }
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.off, 0, 0, W, W);
    const px = (x, y) => [((x - sc.x_offset) / sc.x_real) * W, W - ((y - sc.y_offset) / sc.y_real) * W];
    // The particles as rings that show on any colour of the scan: white over a dark edge.
    for (const p of st.serverParticles ?? []) {
      const [x, y] = px(p.x, p.y);
      const r = Math.max(6, (p.radius / sc.x_real) * W) + 3;
      for (const [w, c] of [[5, 'rgba(0,0,0,.7)'], [2, '#ffffff']]) {
        ctx.lineWidth = w;
        ctx.strokeStyle = c;
        ctx.beginPath();
        ctx.arc(x, y, r, 0, 2 * Math.PI);
        ctx.stroke();
      }
    }
    if (st.tip) {
      const [x, y] = px(st.tip.stage[0], st.tip.stage[1]);
      ctx.fillStyle = '#ff7a3d';
      ctx.beginPath();
      ctx.arc(x, y, 6, 0, 2 * Math.PI);
      ctx.fill();
    }
    const text = `scan ${sc.id}${sc.done ? '' : ` (line ${sc.lines}/${sc.yres})`}${st.scanStale ? ', stale' : ''} · phase ${phase}`;
    cap.textContent = text;
    cv.setAttribute('aria-label', `The latest scan, ${text}, with the particles and the tip`);
  }
}

/** Builds the monitoring page and starts polling and listening. */
export function start() {
  build();
  const m = new Monitor();
  m.poll();
  m.runs();
  setInterval(() => m.poll(), POLL_MS);
  setInterval(() => m.runs(), RUNS_MS);
  setInterval(() => m.draw(), 250);
  m.connect();
  window.nanopushMonitor = m;
}
