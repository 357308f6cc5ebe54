// The monitoring view (`/?view=monitor`): compact and read-only, for a wall screen. The
// instrument's phase, the control loop's health, the haptic link and its device's faults
// (`deviceFaultsLine`, src/devicefaults.js), clients and the lease (from /api/status, every
// second), and the last runs (run_done events on a viewer WebSocket, with no
// streams). No controls; needs no npm packages. Nothing animates: each update writes its text
// at once. `statusTiles` is pure (Node tests); `start()` (src/main.js) builds the page.
import { Session, describeRun } from './session.js';
import { wsUrl, apiUrl, backoffMs } from './connection.js';
import { deviceFaultsLine } from './devicefaults.js';

const POLL_MS = 1000;

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
    h('p', { id: 'm-conn', class: 'm-conn' }, 'connecting…'),
    h('dl', { class: 'tiles' },
      tile('m-phase', 'Instrument phase'),
      tile('m-loop', 'Control loop'),
      tile('m-jitter', 'Period error p99'),
      tile('m-haptic', 'Haptic link'),
      tile('m-clients', 'Clients'),
      tile('m-lease', 'Lease'),
      tile('m-uptime', 'Uptime'),
      tile('m-hapdev', 'Haptic device', 'tile wide')),
    h('section', { 'aria-labelledby': 'm-runs-h' },
      h('h2', { id: 'm-runs-h' }, 'Last runs'),
      h('ol', { id: 'm-runs', class: 'm-runs' }, h('li', {}, 'none yet'))));
  document.body.replaceChildren(main);
}

function set(id, text, cls = '') {
  const e = document.getElementById(id);
  e.textContent = text;
  e.className = cls;
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
  return [
    ['m-scene', `· ${s.scene}`, ''],
    ['m-phase', s.phase + (s.busy ? ' (busy)' : ''), ''],
    ['m-loop', `${health}${l.realtime ? ', real-time' : ', not real-time'}`, l.overruns > 0 ? 'warn' : 'good'],
    ['m-jitter', Number.isFinite(p99) ? `≤ ${(p99 * 1e6).toFixed(0)} µs` : '–', ''],
    ['m-haptic', hp.link === 'off' || !hp.link ? 'off' : `${hp.link}${hp.engaged ? ', engaged' : ''}`, hp.link === 'down' ? 'bad' : ''],
    ['m-clients', String(s.clients), ''],
    ['m-lease', s.lease === null ? 'free' : `client ${s.lease}`, ''],
    ['m-uptime', `${Math.floor(s.uptime_s / 60)} min ${Math.floor(s.uptime_s % 60)} s`, ''],
    ['m-hapdev', dev.text, dev.cls],
  ];
}

async function poll() {
  try {
    const r = await fetch(apiUrl('/api/status', location));
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const s = await r.json();
    for (const [id, text, cls] of statusTiles(s)) set(id, text, cls);
    set('m-conn', 'status: live', 'good');
  } catch (e) {
    set('m-conn', `status unavailable: ${e.message}`, 'bad');
  }
}

const runs = [];
function showRuns() {
  const ol = document.getElementById('m-runs');
  if (!runs.length) return;
  ol.replaceChildren(...runs.slice(-8).reverse().map((r) => h('li', { class: r.outcome === 'ok' ? 'good' : 'bad' }, `${r.at.toLocaleTimeString()} ${describeRun(r)}`)));
}

function connect(attempt = 0) {
  const session = new Session();
  let ws;
  try {
    ws = new WebSocket(wsUrl(location));
  } catch {
    setTimeout(() => connect(attempt + 1), backoffMs(attempt + 1));
    return;
  }
  ws.onmessage = (ev) => {
    if (typeof ev.data !== 'string') return;
    const e = session.apply(ev.data);
    if (e.kind === 'run_done') {
      runs.push({ ...e.run, at: new Date() });
      showRuns();
    }
  };
  ws.onclose = () => setTimeout(() => connect(attempt + 1), backoffMs(attempt + 1));
}

/** Builds the monitoring page and starts polling and listening. */
export function start() {
  build();
  poll();
  setInterval(poll, POLL_MS);
  connect();
}
