// The Nano Visulator page: a view of the protocol Session (src/protocol.js), a 3D view
// (src/view3d.js) and strip charts (src/charts.js), wired to `nanopush serve`'s WebSocket.
import { Session, commands, encodeCommand, wsUrl, apiUrl, backoffMs, controlState, STREAMS } from './protocol.js';
import { View3D, formatLength } from './view3d.js';
import { Charts } from './charts.js';
import { viridisCss } from './colormap.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const demo = params.has('demo');

const session = new Session();
const st = session.state;
let ws = null;
let attempt = 0;
let reconnectTimer = null;
let countdownTimer = null;
let selected = null; // particle id
let exagTouched = false;
const replyEl = { take_lease: 'reply-lease', release_lease: 'reply-lease', push: 'reply-push', scan: 'reply-scan', stop: 'reply-stop' };
const lastIdByOutput = new Map(); // output element id → latest command id shown there

const view = new View3D($('view3d'), {
  onPickPoint: (x, y) => pickTarget(x, y),
  onPickParticle: (id) => selectParticle(id),
});
const charts = new Charts($('chart-volts'), $('chart-z'));
$('legend-bar').style.background = `linear-gradient(to right, ${viridisCss()})`;

// ----- connection -----

function connect() {
  clearTimeout(reconnectTimer);
  session.connecting();
  render();
  const url = wsUrl(location);
  let sock;
  if (demo) {
    sock = null;
    import('./demo.js').then(({ DemoSocket }) => attach(new DemoSocket(url, params.get('role') || 'operator')));
    return;
  }
  try {
    sock = new WebSocket(url);
  } catch (e) {
    session.logError('client_socket', e.message);
    scheduleReconnect();
    return;
  }
  attach(sock);
}

function attach(sock) {
  ws = sock;
  sock.binaryType = 'arraybuffer';
  sock.onopen = () => {
    attempt = 0;
    session.opened();
    logEvent('connected', 'good');
    render();
  };
  sock.onmessage = (ev) => onMessage(ev.data);
  sock.onclose = (ev) => {
    if (ws !== sock) return;
    ws = null;
    const why = st.shutdown !== null ? `server shut down: ${st.shutdown}` : `closed (code ${ev.code}${ev.reason ? `, ${ev.reason}` : ''})`;
    logEvent(`connection ${why}`, 'bad');
    scheduleReconnect();
  };
  sock.onerror = () => {};
}

function scheduleReconnect() {
  attempt++;
  const delay = backoffMs(attempt);
  session.closed(attempt, delay);
  const due = Date.now() + delay;
  clearInterval(countdownTimer);
  const tick = () => {
    const left = Math.max(0, due - Date.now());
    setConn('closed', `reconnecting in ${(left / 1000).toFixed(1)} s (attempt ${attempt})`);
    if (left <= 0) clearInterval(countdownTimer);
  };
  countdownTimer = setInterval(tick, 250);
  render();
  tick();
  reconnectTimer = setTimeout(() => {
    clearInterval(countdownTimer);
    connect();
  }, delay);
}

function send(msg) {
  if (!ws || ws.readyState !== 1) {
    session.logError('client_socket', 'not connected: the command was not sent');
    render();
    return null;
  }
  const m = session.issue(msg);
  const out = replyEl[m.type];
  if (out) {
    lastIdByOutput.set(out, m.id);
    showReply(out, 'pending', `#${m.id} sent…`);
  }
  ws.send(encodeCommand(m));
  return m;
}

// ----- server messages -----

function onMessage(data) {
  const ev = session.apply(data);
  switch (ev.kind) {
    case 'welcome':
      send(commands.subscribe(STREAMS));
      loadScene();
      logEvent(`welcome: client ${st.client}, ${st.role}, scene ${st.scene}, ${st.tickHz} Hz`);
      break;
    case 'telemetry':
      view.setTip(st.tip);
      charts.update(st.trace);
      renderTip();
      if (st.tip.phase !== lastPhase) {
        lastPhase = st.tip.phase;
        renderStatus();
      }
      return; // 60 Hz: skip the full render
    case 'scan_start':
      view.startScan(st.scan);
      $('legend').hidden = false;
      logEvent(`scan ${st.scan.id} started: ${st.scan.xres}×${st.scan.yres} px, ${formatLength(st.scan.x_real)} square`);
      if (!scanFramed) {
        view.frameScan();
        scanFramed = true;
      }
      view.updateParticles(st.particles, selected);
      updatePreview();
      renderLegend();
      return;
    case 'scan_line':
      view.scanLine(st.scan, ev.line);
      renderLegend();
      return;
    case 'scan_done':
      logEvent(`scan done${ev.record ? `: ${ev.record}` : ''}`, 'good');
      if (!exagTouched) autoExaggeration();
      renderLegend();
      refreshRecords();
      break;
    case 'run_done': {
      const r = ev.run;
      const ok = r.outcome === 'ok';
      logEvent(`push of #${r.particle}: ${r.outcome}${r.failure ? ` (${r.failure})` : ''}, ends at (${(r.estimate[0] * 1e6).toFixed(2)}, ${(r.estimate[1] * 1e6).toFixed(2)}) µm`, ok ? 'good' : 'bad');
      view.updateParticles(st.particles, selected);
      updatePreview();
      refreshRecords();
      break;
    }
    case 'reply':
      if (ev.command) {
        const out = replyEl[ev.command.type];
        if (out && lastIdByOutput.get(out) === ev.id) {
          const c = ev.command;
          showReply(out, c.status, c.status === 'ok' ? `#${c.id} ok` : `#${c.id} ${c.code}: ${c.message}`);
        }
      }
      if (!ev.ok) logEvent(`error${ev.id !== null ? ` #${ev.id}` : ''} ${st.lastError.code}: ${st.lastError.message}`, 'bad');
      break;
    case 'lagged':
      break;
    case 'lease':
      logEvent(st.lease === null ? 'lease released' : st.lease === st.client ? 'you hold the lease' : `client ${st.lease} holds the lease`);
      break;
    case 'shutdown':
      logEvent(`server shutting down: ${st.shutdown}`, 'bad');
      break;
    case 'error':
      logEvent(`${st.lastError.code}: ${st.lastError.message}`, 'bad');
      break;
    default:
      break;
  }
  render();
}
let lastPhase = null;
let scanFramed = false;

// ----- scene, particles, records -----

async function loadScene() {
  if (demo) {
    const { demoScene } = await import('./demo.js');
    applyScene(demoScene());
    return;
  }
  try {
    const r = await fetch(apiUrl('/api/scene', location));
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    applyScene(await r.json());
  } catch (e) {
    logEvent(`could not load /api/scene: ${e.message}`, 'bad');
  }
}

function applyScene(scene) {
  session.setScene(scene);
  $('scene-name').textContent = scene.name ? `· ${scene.name}` : '';
  const range = st.stageRange * 1e6;
  view.setStage(range);
  for (const id of ['to-x', 'to-y', 'scan-x', 'scan-y']) $(id).max = String(range);
  const sel = $('particle');
  sel.replaceChildren(...st.particles.map((p) => {
    const o = document.createElement('option');
    o.value = String(p.id);
    o.textContent = `#${p.id}${p.material ? ` ${p.material}` : ''} (r ${formatLength(p.radius)})`;
    return o;
  }));
  if (!st.particles.some((p) => p.id === selected)) selected = st.particles[0]?.id ?? null;
  if (selected !== null) sel.value = String(selected);
  view.setParticles(st.particles, selected);
  if (!st.scan) view.frameStage();
  if ($('scan-x').value === '') centreScanOnParticle();
  updatePreview();
}

function selectParticle(id) {
  selected = id;
  $('particle').value = String(id);
  view.updateParticles(st.particles, selected);
  updatePreview();
}

function pickTarget(xUm, yUm) {
  const r = st.stageRange * 1e6;
  const x = Math.min(r, Math.max(0, xUm));
  const y = Math.min(r, Math.max(0, yUm));
  $('to-x').value = x.toFixed(2);
  $('to-y').value = y.toFixed(2);
  document.querySelector('input[name=mode][value=to]').checked = true;
  setMode('to');
  updatePreview();
}

function centreScanOnParticle() {
  const p = st.particles.find((q) => q.id === selected);
  if (!p) return;
  $('scan-x').value = (p.x * 1e6).toFixed(2);
  $('scan-y').value = (p.y * 1e6).toFixed(2);
}

async function refreshRecords() {
  const body = $('records');
  if (demo) {
    body.replaceChildren(row(['(demo: no records)'], 4));
    return;
  }
  try {
    const r = await fetch(apiUrl('/api/records', location));
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const list = await r.json();
    if (!list.length) {
      body.replaceChildren(row(['no records yet'], 4));
      return;
    }
    list.sort((a, b) => String(b.modified).localeCompare(String(a.modified)));
    body.replaceChildren(...list.map((rec) => {
      const tr = document.createElement('tr');
      const a = document.createElement('a');
      a.href = apiUrl(`/api/records/${encodeURIComponent(rec.name)}`, location);
      a.download = rec.name;
      a.textContent = rec.name;
      const cells = [a, rec.kind ?? '', formatBytes(rec.bytes), formatTime(rec.modified)];
      for (const c of cells) {
        const td = document.createElement('td');
        td.append(c);
        tr.append(td);
      }
      return tr;
    }));
  } catch (e) {
    body.replaceChildren(row([`could not list records: ${e.message}`], 4));
  }
}

function row(texts, span) {
  const tr = document.createElement('tr');
  for (const t of texts) {
    const td = document.createElement('td');
    td.colSpan = span;
    td.textContent = t;
    tr.append(td);
  }
  return tr;
}

function formatBytes(n) {
  if (typeof n !== 'number') return '';
  if (n < 1024) return `${n} B`;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(1)} KiB`;
  return `${(n / 1024 / 1024).toFixed(1)} MiB`;
}

function formatTime(t) {
  if (t === undefined || t === null) return '';
  const d = typeof t === 'number' ? new Date(t < 1e12 ? t * 1000 : t) : new Date(t);
  return Number.isNaN(d.getTime()) ? String(t) : d.toLocaleString();
}

// ----- rendering the state -----

function setConn(kind, text) {
  const el = $('st-conn');
  el.className = `conn-${kind}`;
  el.querySelector('.txt').textContent = text;
}

function render() {
  renderStatus();
  renderControls();
}

function renderStatus() {
  if (st.connection === 'open') setConn('open', demo ? 'demo (no server)' : 'connected');
  else if (st.connection === 'connecting') setConn('connecting', 'connecting…');
  else if (!st.reconnect) setConn('closed', 'closed');
  $('st-role').textContent = st.role ?? '–';
  $('st-client').textContent = st.client ?? '–';
  const lease = $('st-lease');
  lease.textContent = st.lease === null ? 'free' : st.lease === st.client ? `you (${st.lease})` : `client ${st.lease}`;
  lease.className = st.lease !== null && st.lease === st.client ? 'mine' : '';
  $('st-phase').textContent = st.phase ?? '–';
  $('st-lagged').textContent = st.lagged.events ? `${st.lagged.events}× (${st.lagged.skipped} msgs)` : '0';
  const e = st.lastError;
  const err = $('st-error');
  err.textContent = e ? `${e.code}${e.id !== null ? ` (#${e.id}${e.command ? ` ${e.command}` : ''})` : ''}: ${e.message}` : 'none';
  err.title = err.textContent;
  err.className = e ? 'err' : '';
}

function renderControls() {
  const c = controlState(st);
  const set = (el, s) => {
    el.disabled = !s.enabled;
    el.title = s.why;
  };
  set($('take-lease'), c.takeLease);
  set($('release-lease'), c.releaseLease);
  set($('push-fs'), c.push);
  set($('scan-fs'), c.scan);
  set($('stop-btn'), c.stop);
  // Buttons inside a disabled fieldset: give them the reason as a tooltip too.
  $('push-btn').title = c.push.why;
  $('scan-btn').title = c.scan.why;
  $('why').textContent = c.push.enabled ? '' : c.push.why;
}

function renderTip() {
  const t = st.tip;
  if (!t) return;
  const [x, y, z] = t.stage;
  $('tipinfo').textContent = `tip x ${(x * 1e6).toFixed(3)} µm · y ${(y * 1e6).toFixed(3)} µm · z ${(z * 1e9).toFixed(1)} nm · ${t.volts.toFixed(3)} V · ${t.phase}` +
    (t.estimate ? ` · particle at (${(t.estimate[0] * 1e6).toFixed(2)}, ${(t.estimate[1] * 1e6).toFixed(2)}) µm` : '');
}

function renderLegend() {
  const sc = st.scan;
  if (!sc) return;
  const r = view.colourScale();
  if (r) {
    $('legend-lo').textContent = formatLength(r.lo);
    $('legend-hi').textContent = formatLength(r.hi);
  }
  $('scan-progress').textContent = sc.done ? `scan ${sc.id} complete` : `scan ${sc.id}: line ${sc.lines}/${sc.yres}`;
}

function showReply(id, status, text) {
  const el = $(id);
  el.className = `reply ${status}`;
  el.textContent = text;
}

function logEvent(text, cls = '') {
  const li = document.createElement('li');
  const time = document.createElement('time');
  const now = new Date();
  time.dateTime = now.toISOString();
  time.textContent = now.toLocaleTimeString();
  const span = document.createElement('span');
  span.className = cls;
  span.textContent = text;
  li.append(time, span);
  const log = $('log');
  log.prepend(li);
  while (log.children.length > 60) log.lastChild.remove();
}

// ----- exaggeration -----

function setExaggeration(x) {
  const v = Math.min(1000, Math.max(1, x));
  $('exag').value = String(Math.log10(v));
  $('exag-val').textContent = v < 10 ? v.toFixed(1) : v.toFixed(0);
  view.setExaggeration(v);
}

function autoExaggeration() {
  const sc = st.scan;
  if (!sc || !(sc.max > sc.min)) return;
  const side = Math.min(sc.x_real, sc.y_real);
  setExaggeration((0.15 * side) / (sc.max - sc.min));
}

// ----- controls -----

function mode() {
  return document.querySelector('input[name=mode]:checked').value;
}

function setMode(m) {
  $('by-fields').hidden = m !== 'by';
  $('to-fields').hidden = m !== 'to';
}

function num(id) {
  const v = $(id).value.trim();
  return v === '' ? undefined : Number(v);
}

function updatePreview() {
  const p = st.particles.find((q) => q.id === selected);
  if (!p) {
    view.setPreview(null);
    view.setTarget(null);
    return;
  }
  const from = { x: p.x * 1e6, y: p.y * 1e6, z: p.radius * 1e6 };
  if (mode() === 'by') {
    view.setTarget(null);
    view.setPreview(from, num('direction') ?? 0, num('distance') ?? 0);
  } else {
    const tx = num('to-x');
    const ty = num('to-y');
    if (tx === undefined || ty === undefined) {
      view.setPreview(null);
      view.setTarget(null);
      return;
    }
    view.setTarget(tx, ty);
    const dx = tx - from.x;
    const dy = ty - from.y;
    view.setPreview(from, (Math.atan2(dy, dx) * 180) / Math.PI, Math.hypot(dx, dy));
  }
}

function guarded(out, build) {
  try {
    send(build());
  } catch (e) {
    showReply(out, 'error', `not sent: ${e.message}`);
  }
}

$('take-lease').addEventListener('click', () => guarded('reply-lease', () => commands.takeLease()));
$('release-lease').addEventListener('click', () => guarded('reply-lease', () => commands.releaseLease()));
$('stop-btn').addEventListener('click', () => guarded('reply-stop', () => commands.stop()));
$('push-form').addEventListener('submit', (e) => {
  e.preventDefault();
  const particle = Number($('particle').value);
  guarded('reply-push', () => (mode() === 'by'
    ? commands.pushBy(particle, num('distance'), num('direction'))
    : commands.pushTo(particle, num('to-x'), num('to-y'), undefined, st.stageRange * 1e6)));
});
$('scan-form').addEventListener('submit', (e) => {
  e.preventDefault();
  scanFramed = false;
  guarded('reply-scan', () => commands.scan({ centreXUm: num('scan-x'), centreYUm: num('scan-y'), sizeUm: num('scan-size'), pixels: num('scan-px') }));
});
$('scan-centre').addEventListener('click', centreScanOnParticle);
$('particle').addEventListener('change', () => selectParticle(Number($('particle').value)));
for (const r of document.querySelectorAll('input[name=mode]')) r.addEventListener('change', () => {
  setMode(mode());
  updatePreview();
});
for (const id of ['distance', 'direction', 'to-x', 'to-y']) $(id).addEventListener('input', updatePreview);
$('exag').addEventListener('input', () => {
  exagTouched = true;
  setExaggeration(10 ** Number($('exag').value));
});
$('exag-auto').addEventListener('click', () => {
  exagTouched = false;
  autoExaggeration();
});
$('frame-stage').addEventListener('click', () => view.frameStage());
$('frame-scan').addEventListener('click', () => view.frameScan());
$('clear-trail').addEventListener('click', () => view.clearTrail());
$('rec-refresh').addEventListener('click', refreshRecords);
document.addEventListener('keydown', (e) => {
  if (e.key === 'Escape' && !$('stop-btn').disabled) {
    e.preventDefault();
    $('stop-btn').click();
  }
});

setExaggeration(1);
render();
loadScene();
refreshRecords();
connect();

// For tests and the curious: the state the page shows.
window.nanopush = { session, view };
