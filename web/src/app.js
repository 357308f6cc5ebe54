// The Nano Visulator page: a view of the protocol Session (src/protocol.js), a 3D view
// (src/view3d.js), the 2D height image with its line profile (src/image2d.js) and force plots
// (src/charts.js), wired to `nanopush serve`'s WebSocket. Messages change the Session and mark
// what is dirty; one animation frame redraws what is dirty (never once per message).
import { Session, commands, encodeCommand, wsUrl, apiUrl, backoffMs, controlState, STREAMS, describeRun, parseGsf, setPointForceN } from './protocol.js';
import { View3D, formatLength } from './view3d.js';
import { Image2D } from './image2d.js';
import { Charts, traceCsv } from './charts.js';
import { HapticPanel } from './haptic.js';
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
let scanCentreTouched = false;
let scanFormTouched = false;
const replyEl = { take_lease: 'reply-lease', release_lease: 'reply-lease', push: 'reply-push', scan: 'reply-scan', stop: 'reply-stop', haptic: 'reply-haptic' };
const lastIdByOutput = new Map(); // output element id → latest command id shown there

const view = new View3D($('view3d'), {
  onPickPoint: (x, y) => pickTarget(x, y),
  onPickParticle: (id) => selectParticle(id),
});
const image2d = new Image2D($('image2d'), { cursorEl: $('img-cursor'), profileEl: $('profile'), profileInfoEl: $('profile-info') });
const charts = new Charts($('chart-force'), $('chart-z'), $('chart-fd'));
const haptic = new HapticPanel({
  panel: $('haptic-panel'),
  plot: $('chart-hap'),
  fields: { link: $('hap-link'), phase: $('hap-phase'), engaged: $('hap-engaged'), handle: $('hap-handle'), hand: $('hap-hand'), tip: $('hap-tip'), pc: $('hap-pc') },
});
const outcomes = new Map(); // record name → run_done, for the records' outcome column
let openedRecord = null; // a past scan opened from the records (not the live one)

// ----- redraw on change, once per animation frame -----

const dirty = new Set();
let framePending = false;
function mark(...what) {
  for (const w of what) dirty.add(w);
  if (!framePending) {
    framePending = true;
    requestAnimationFrame(flush);
  }
}
let lastLive = 0;
/**
 * The live views (tip, its text, the plots) follow telemetry every frame while the browser
 * keeps up; when its frames are slow (a software renderer, a busy machine) they refresh less
 * often (three frame times apart, at least 250 ms, at most 1 s), so frames stay free for what the operator does:
 * a Stop click and its reply are never queued behind tip updates.
 */
function livePeriodMs() {
  const f = view.frameInterval;
  return f > 40 ? Math.min(1000, Math.max(250, 3 * f)) : 0;
}
function flush(now) {
  framePending = false;
  if (dirty.has('status')) renderStatus();
  if (dirty.has('legend')) renderLegend();
  dirty.delete('status');
  dirty.delete('legend');
  if (dirty.size && now - lastLive >= livePeriodMs()) {
    lastLive = now;
    if (dirty.has('tip')) {
      view.setTip(st.tip);
      renderTip();
      haptic.update(st.tip?.t, st.tip?.haptic);
    }
    if (dirty.has('charts')) charts.update(st.trace);
    dirty.clear();
  }
  if (dirty.size && !framePending) {
    framePending = true;
    requestAnimationFrame(flush);
  }
}
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
    // The shutdown message was logged when it came: do not say it twice.
    if (st.shutdown === null) logEvent(`connection closed (code ${ev.code}${ev.reason ? `, ${ev.reason}` : ''})`, 'bad');
    if (session.hasLease) {
      // The server frees the lease of a connection that closes, and stops its push or scan.
      const t = 'you lost the lease: the connection closed (the server stops a push or scan whose lease holder is gone); take it again once reconnected';
      logEvent(t, 'bad');
      announce(t);
    }
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
    case 'state':
      onState(ev);
      break;
    case 'telemetry':
      mark('tip', 'charts');
      if (st.tip.phase !== lastPhase) {
        lastPhase = st.tip.phase;
        mark('status');
      }
      return; // 60 Hz: drawn in the next animation frame, with whatever else changed
    case 'scan_start':
      openedRecord = null;
      showScan();
      logEvent(`scan ${st.scan.id} started: ${st.scan.xres}×${st.scan.yres} px, ${formatLength(st.scan.x_real)} square`);
      if (!scanFramed) {
        view.frameScan();
        scanFramed = true;
      }
      return;
    case 'scan_line':
      if (openedRecord) return; // a past scan is shown; the live one fills the Session only
      view.scanLine(st.scan, ev.line);
      image2d.invalidate();
      mark('legend');
      return;
    case 'scan_done':
      logEvent(ev.record ? `scan done: ${ev.record}` : ev.record_error ? `scan done, no record: ${ev.record_error}` : 'scan cancelled', ev.record ? 'good' : 'bad');
      if (!exagTouched) autoExaggeration();
      renderLegend();
      refreshRecords();
      break;
    case 'push_started': {
      const p = ev.push;
      const end = p.path[p.path.length - 1];
      const who = p.by === st.client ? 'you' : `client ${p.by}`;
      logEvent(`push started: #${p.particle} by ${who}, to (${(end[0] * 1e6).toFixed(3)}, ${(end[1] * 1e6).toFixed(3)}) µm in ${p.path.length - 1} leg${p.path.length > 2 ? 's' : ''}`);
      charts.restartFd(st.tip?.t ?? -Infinity);
      renderPush();
      break;
    }
    case 'run_done': {
      const r = ev.run;
      const text = describeRun(r);
      logEvent(text, r.outcome === 'ok' ? 'good' : 'bad');
      showLastRun(r, text);
      announce(text);
      if (r.record) outcomes.set(r.record, r);
      view.updateParticles(st.particles, selected);
      renderPush();
      renderStale();
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
    case 'lease': {
      const now = st.lease === null ? 'the lease is free' : st.lease === st.client ? 'you hold the lease' : `client ${st.lease} holds the lease`;
      if (ev.lost) {
        const t = `you lost the lease: ${ev.reason ?? now}`;
        logEvent(t, 'bad');
        announce(t);
      } else {
        logEvent(ev.reason ? `${now}: ${ev.reason}` : now, ev.reason ? 'bad' : '');
        if (ev.reason) announce(ev.reason);
      }
      renderPush();
      break;
    }
    case 'shutdown':
      logEvent(`server shutting down: ${st.shutdown}`, 'bad');
      announce(`server shutting down: ${st.shutdown}`);
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

/** The server's `state`: particles, lease, phase, the push running and the latest scan. */
function onState(ev) {
  view.updateParticles(st.particles, selected);
  if (selected !== null && $('scan-x').value !== '' && !scanCentreTouched) centreScanOnParticle();
  if (st.tip) mark('tip');
  if (ev.scanChanged && !openedRecord) {
    showScan();
    if (st.scan.done && st.scan.record) loadLatestScan(st.scan.id, st.scan.record);
  }
  renderPush();
  renderStale();
  logEvent(`state: phase ${st.phase ?? '–'}, ${st.lease === null ? 'lease free' : `lease held by client ${st.lease}`}${st.push ? `, pushing #${st.push.particle}` : ''}${st.scan ? `, latest scan ${st.scan.record ?? st.scan.id}${st.scanStale ? ' (stale)' : ''}` : ''}`);
}

/** Shows the Session's scan (new, or refilled) in both views. */
function showScan() {
  view.startScan(st.scan);
  if (st.scan.lines) view.fillScan(st.scan);
  image2d.setScan(st.scan);
  $('legend').hidden = false;
  $('img-title').textContent = openedRecord ? `· record ${openedRecord}` : `· scan ${st.scan.id}`;
  view.updateParticles(st.particles, selected);
  renderStale();
  renderLegend();
}

/** A late joiner's latest scan: its heights from the record the server names. */
async function loadLatestScan(id, record) {
  try {
    const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(record)}`, location));
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const g = parseGsf(await r.arrayBuffer());
    if (!session.fillScan(id, g.heights)) return; // another scan started meanwhile
    view.fillScan(st.scan);
    image2d.invalidate();
    if (!exagTouched) autoExaggeration();
    if (!scanFramed) {
      view.frameScan();
      scanFramed = true;
    }
    renderLegend();
  } catch (e) {
    logEvent(`could not load the latest scan ${record}: ${e.message}`, 'bad');
  }
}

/** A past scan from the records, shown until the next live scan starts. */
async function openScanRecord(name) {
  try {
    const r = await fetch(apiUrl(`/api/records/${encodeURIComponent(name)}`, location));
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const g = parseGsf(await r.arrayBuffer());
    const s = new Session();
    s.startScan({ scan: -1, xres: g.xres, yres: g.yres, x_offset: g.x_offset, y_offset: g.y_offset, x_real: g.x_real, y_real: g.y_real });
    s.fillScan(-1, g.heights);
    openedRecord = name;
    const sc = s.state.scan;
    view.startScan(sc);
    view.fillScan(sc);
    image2d.setScan(sc);
    $('img-title').textContent = `· record ${name}`;
    $('img-stale').hidden = true;
    view.frameScan();
    logEvent(`opened ${name}: ${g.xres}×${g.yres} px, ${formatLength(g.x_real)} square`);
  } catch (e) {
    logEvent(`could not open ${name}: ${e.message}`, 'bad');
  }
}

function renderStale() {
  const stale = st.scanStale && !openedRecord && !!st.scan;
  $('img-stale').hidden = !stale;
  $('scan-progress').classList.toggle('stale', stale);
  mark('legend');
}

/** The push running (everyone's view of it) or, for the lease holder, the form's preview. */
function renderPush() {
  const p = st.push;
  const el = $('push-now');
  if (p) {
    view.setPushPath(p.path);
    view.setPreview(null);
    view.setTarget(null);
    const end = p.path[p.path.length - 1];
    el.textContent = `Pushing #${p.particle} (${p.by === st.client ? 'you' : `client ${p.by}`}) to (${(end[0] * 1e6).toFixed(3)}, ${(end[1] * 1e6).toFixed(3)}) µm`;
    el.hidden = false;
  } else {
    view.setPushPath(null);
    el.hidden = true;
    updatePreview();
  }
}

function showLastRun(r, text) {
  const el = $('lastrun');
  el.textContent = text;
  el.className = `lastrun ${r.outcome === 'ok' ? 'good' : 'bad'}`;
  el.hidden = false;
}

/** Says something to screen readers (only what matters: runs, the lease, shutdown). */
function announce(text) {
  const el = $('announce');
  el.textContent = '';
  setTimeout(() => {
    el.textContent = text;
  }, 50);
}

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
  charts.setSetPoint(setPointForceN(scene));
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
  // The scan form starts at the scene's own scan (a 14 nm particle is not imaged 10 µm wide).
  if (!scanFormTouched && scene.scan) {
    if (Number.isFinite(scene.scan.size_um)) $('scan-size').value = String(scene.scan.size_um);
    if (Number.isFinite(scene.scan.pixels)) $('scan-px').value = String(Math.min(512, Math.max(8, scene.scan.pixels)));
  }
  renderPush();
}

function selectParticle(id) {
  selected = id;
  $('particle').value = String(id);
  view.updateParticles(st.particles, selected);
  renderPush();
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
    body.replaceChildren(row(['(demo: no records)'], 5));
    return;
  }
  try {
    const r = await fetch(apiUrl('/api/records', location));
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const list = await r.json();
    if (!list.length) {
      body.replaceChildren(row(['no records yet'], 5));
      return;
    }
    list.sort((a, b) => String(b.modified).localeCompare(String(a.modified)));
    body.replaceChildren(...list.map((rec) => {
      const tr = document.createElement('tr');
      const a = document.createElement('a');
      a.href = apiUrl(`/api/records/${encodeURIComponent(rec.name)}`, location);
      a.download = rec.name;
      a.textContent = rec.name;
      const first = document.createElement('span');
      first.append(a);
      if (rec.name.endsWith('.gsf')) {
        const b = document.createElement('button');
        b.type = 'button';
        b.className = 'small';
        b.textContent = 'Open';
        b.setAttribute('aria-label', `Open ${rec.name} in the views`);
        b.addEventListener('click', () => openScanRecord(rec.name));
        first.append(' ', b);
      }
      const run = outcomes.get(rec.name);
      const outcome = run ? (run.outcome === 'ok' ? 'ok' : `${run.outcome}: ${run.failure ?? ''}`) : '';
      const cells = [first, rec.kind ?? '', outcome, formatBytes(rec.bytes), formatTime(rec.modified)];
      for (const c of cells) {
        const td = document.createElement('td');
        td.append(c);
        tr.append(td);
      }
      return tr;
    }));
  } catch (e) {
    body.replaceChildren(row([`could not list records: ${e.message}`], 5));
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
  set($('hap-fs'), c.haptic);
  // Buttons inside a disabled fieldset: give them the reason as a tooltip too.
  $('push-btn').title = c.push.why;
  $('scan-btn').title = c.scan.why;
  $('why').textContent = c.push.enabled ? '' : c.push.why;
}

function renderTip() {
  const t = st.tip;
  if (!t) return;
  const [x, y, z] = t.stage;
  $('tipinfo').textContent = `tip x ${(x * 1e6).toFixed(3)} µm · y ${(y * 1e6).toFixed(3)} µm · z ${(z * 1e9).toFixed(1)} nm · force ${((t.force ?? 0) * 1e9).toFixed(2)} nN · ${t.volts.toFixed(3)} V · ${t.phase}` +
    (t.estimate ? ` · particle at (${(t.estimate[0] * 1e6).toFixed(3)}, ${(t.estimate[1] * 1e6).toFixed(3)}) µm` : '');
}

function renderLegend() {
  const sc = st.scan;
  if (!sc) return;
  const r = view.colourScale();
  if (r) {
    $('legend-lo').textContent = formatLength(r.lo);
    $('legend-hi').textContent = formatLength(r.hi);
  }
  $('scan-progress').textContent = (sc.done ? `scan ${sc.id} complete` : `scan ${sc.id}: line ${sc.lines}/${sc.yres}`) + (st.scanStale ? ' · stale (a push ran since)' : '');
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

/** The form's push preview: only the lease holder's own, and only while no push runs (viewers
 * see the operator's commanded path instead, from `push_started` / `state`). */
function updatePreview() {
  const p = st.particles.find((q) => q.id === selected);
  if (!p || st.push || !session.hasLease) {
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
// Stop goes on the pointer's press, not its release (a click): one event sooner. The click that
// follows is then ignored; a keyboard's Enter or Space still clicks.
let stopPressed = false;
$('stop-btn').addEventListener('pointerdown', (e) => {
  if (e.button !== 0 || $('stop-btn').disabled) return;
  stopPressed = true;
  guarded('reply-stop', () => commands.stop());
});
$('stop-btn').addEventListener('click', () => {
  if (stopPressed) {
    stopPressed = false;
    return;
  }
  guarded('reply-stop', () => commands.stop());
});
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
$('scan-centre').addEventListener('click', () => {
  scanCentreTouched = false;
  centreScanOnParticle();
});
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
$('frame-tip').addEventListener('click', () => view.frameTip());
for (const a of ['engage', 'release', 'recenter']) $(`hap-${a}`).addEventListener('click', () => guarded('reply-haptic', () => commands.haptic(a)));
$('hap-scale').addEventListener('click', () => guarded('reply-haptic', () => commands.haptic('scale', { nmPerMm: num('hap-nm'), pullOffAtHandN: num('hap-po') })));
$('level').addEventListener('change', () => image2d.setLevelling($('level').value));
$('scan-x').addEventListener('input', () => { scanCentreTouched = true; });
for (const id of ['scan-size', 'scan-px']) $(id).addEventListener('input', () => { scanFormTouched = true; });
$('scan-y').addEventListener('input', () => { scanCentreTouched = true; });
$('csv').addEventListener('click', () => {
  const blob = new Blob([traceCsv(st.trace)], { type: 'text/csv' });
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = `nanopush-trace-${new Date().toISOString().replace(/[:.]/g, '-')}.csv`;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
});
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
window.nanopush = { session, view, image2d, charts, haptic };
