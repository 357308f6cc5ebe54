// The Nano Visulator page, wired: the protocol Session (src/session.js) over the Connection
// (src/connection.js), the 3D view (src/view3d.js), the 2D height image with its line profile
// (src/image2d.js), the force plots (src/charts.js), the haptic panel (src/haptic.js), the status
// bar, controls, event log, records and the scan shown (src/status.js, controls.js, eventlog.js,
// records.js, scans.js, toolbar.js); the haptic panel polls /api/status for the device's faults
// (src/devicefaults.js). Messages change the Session and mark what is dirty; the one
// animation-frame loop (src/frame.js) redraws what is dirty, never once per message. This module
// owns no logic of its own: it builds the parts, routes the Session's events to them and holds
// the one piece of state no part owns (the phase the status bar last showed).
import { commands, STREAMS } from './wire.js';
import { Session, describeRun, runClass, setPointForceN, lostPushRun } from './session.js';
import { Connection, wsUrl, apiUrl } from './connection.js';
import { FrameScheduler, livePeriodFor, liveSlotMs } from './frame.js';
import { formatTip } from './format.js';
import { View3DHost, softwareGl } from './view3dhost.js';
import { Image2D } from './image2d.js';
import { Charts, downloadCsv } from './charts.js';
import { HapticPanel } from './haptic.js';
import { fetchStatus } from './devicefaults.js';
import { StatusBar } from './status.js';
import { Controls, Replies, pushEndedText } from './controls.js';
import { PushStatus } from './pushstatus.js';
import { EventLog, LEASE_LOST_ON_CLOSE, lostOnCloseText, welcomeText, stateText, pushStartedText, pushStrategy, pushWarnings, leaseNote, replyErrorText, closedText, restartText, lostPushText, hapticLinkNote, clockTime } from './eventlog.js';
import { MapOverlay } from './mapoverlay.js';
import { Records } from './records.js';
import { Scans } from './scans.js';
import { Toolbar } from './toolbar.js';
import { AssembleHost } from './assemblehost.js';
import { assemblyLogLine } from './assemblyreport.js';

export class App {
  /**
   * @param {Document} doc
   * @param {Location} loc the page's location: `?token=` (operator), `?demo`, `?role=viewer`
   */
  constructor(doc, loc) {
    const $ = (id) => doc.getElementById(id);
    this.$ = $;
    this.doc = doc;
    this.loc = loc;
    const params = new URLSearchParams(loc.search);
    this.demo = params.has('demo');
    this.session = new Session();
    this.st = this.session.state;
    this.lastPhase = null; // the phase the status bar shows: telemetry redraws it on a change

    // The one animation-frame loop. The page's own parts register first (status bar, legend,
    // the live views), so what they change in the views is drawn in the same frame. The live
    // views follow telemetry every frame while the browser keeps up, less often when its frames
    // are slow (livePeriodMs).
    const frames = new FrameScheduler();
    this.frames = frames;
    this.statusFrame = frames.register('status', () => this.status.render(this.st));
    this.legendFrame = frames.register('legend', () => this.scans.renderLegend());
    // On a software renderer the live views change in the same frames, one a slot (liveSlotMs).
    const software = softwareGl();
    const slot = () => liveSlotMs(software, this.view.shown);
    this.liveFrame = frames.register('live', (parts) => this.drawLive(parts), { period: () => livePeriodFor(frames.frameInterval, slot()), aligned: software });
    // The tip's numbers: read by people, so 5 a second (at 60 a second the text's repaint cost a
    // software renderer a third of its frames).
    this.tipTextFrame = frames.register('tiptext', () => {
      if (this.st.tip && this.st.connection === 'open') this.$('tipinfo').textContent = formatTip(this.st.tip);
    }, { period: 200, aligned: true });

    // The 3D view's host: three.js is loaded when the view is first opened.
    this.view = new View3DHost($('view3d'), {
      onPickPoint: (x, y) => this.controls.pickTarget(x, y),
      onPickParticle: (id) => this.controls.selectParticle(id),
    }, frames, { software, slot });
    this.image2d = new Image2D($('image2d'), { cursorEl: $('img-cursor'), profileEl: $('profile'), profileInfoEl: $('profile-info'), period: slot, onDrawn: () => this.map?.invalidate(),
      // The 3D view coloured as the image: one colour, one height, in both.
      onLevelled: (values, range) => {
        this.view.setColourSource(range ? { values, lo: range.lo, hi: range.hi } : null);
        this.legendFrame?.mark();
      } }, frames);
    // The live map on the height image: particles, tip, path, trail; picking by mouse and keys.
    this.map = new MapOverlay(this.image2d, {
      state: () => this.st,
      selected: () => this.controls.selected,
      onPickParticle: (id) => this.controls.selectParticle(id),
      onPickPoint: (x, y) => this.controls.pickTarget(x, y),
      canTarget: () => this.session.hasLease,
      announce: (text) => this.log.announce(text),
      // A software renderer (no GPU) pays for a whole frame whenever anything moves: the tip in
      // the live slots there, every frame on a GPU.
      livePeriod: slot,
    }, frames);
    this.charts = new Charts($('chart-force'), $('chart-z'), $('chart-fd'), frames);
    this.haptic = new HapticPanel({
      panel: $('haptic-panel'),
      plot: $('chart-hap'),
      fields: { link: $('hap-link'), phase: $('hap-phase'), engaged: $('hap-engaged'), handle: $('hap-handle'), hand: $('hap-hand'), tip: $('hap-tip'), pc: $('hap-pc'), scales: $('hap-scales') },
      device: $('hap-device'),
      downs: $('hap-downs'),
      scales: $('hap-scales'),
      nmInput: $('hap-nm'),
      poInput: $('hap-po'),
    }, frames, {
      doc,
      fetchStatus: this.demo ? undefined : () => fetchStatus(loc),
      onLinkChange: (link, downs) => {
        const n = hapticLinkNote(link, downs);
        this.log.log(n.text, n.cls);
        this.log.announce(n.text);
        this.controls.render();
      },
      onScalesChange: (text) => this.log.log(`haptic scales now ${text}`),
    });

    this.status = new StatusBar($, { demo: this.demo });
    this.log = new EventLog($('log'), $('announce'));
    this.replies = new Replies($);
    this.pushStatus = new PushStatus($, frames, { state: () => this.st, speed: () => this.st.pushSpeed });
    this.conn = new Connection(this.session, {
      url: wsUrl(loc),
      open: (url) => (this.demo
        ? import('./demo.js').then(({ DemoSocket }) => new DemoSocket(url, params.get('role') || 'operator'))
        : new WebSocket(url)),
      onOpen: () => {
        this.log.log('connected', 'good');
        doc.body.classList.remove('offline');
        $('offline').hidden = true;
        this.render();
      },
      onMessage: (data) => this.onMessage(data),
      onClose: (ev, info) => this.onClose(ev, info),
      onCountdown: (text) => this.status.setConn('closed', text),
      onSend: (m) => this.replies.sent(m),
      onChange: () => this.render(),
    });
    this.controls = new Controls($, doc, {
      session: this.session,
      view: this.view,
      map: () => this.map,
      status: this.pushStatus,
      replies: this.replies,
      announce: (text) => this.log.announce(text),
      send: (m) => this.conn.send(m),
      onScanRequested: () => this.scans.requested(),
    });
    // The Assemble panel: its code is loaded when it is first opened or an assembly is seen.
    this.assemble = new AssembleHost($, [$, doc, {
      session: this.session,
      map: this.map,
      send: (m) => this.conn.send(m),
      replies: this.replies,
      announce: (text) => this.log.announce(text),
    }], (e) => this.log.log(`the Assemble panel could not load (${e.message}); open it again once the server is back`, 'bad'));
    this.toolbar = new Toolbar($, this.view, () => this.st.scan);
    this.scans = new Scans($, {
      session: this.session,
      view: this.view,
      image2d: this.image2d,
      map: this.map,
      log: this.log,
      toolbar: this.toolbar,
      loc,
      selected: () => this.controls.selected,
      markLegend: () => this.legendFrame.mark(),
    });
    this.records = new Records($('records'), { loc, demo: this.demo, onOpen: (name) => this.scans.openRecord(name) });

    $('level').addEventListener('change', () => this.image2d.setLevelling($('level').value));
    $('toggle-3d').addEventListener('click', () => this.show3d($('toggle-3d').getAttribute('aria-pressed') !== 'true'));
    // Leaving mid-push stops it (the server stops what a departed lease holder commanded): ask.
    loc && globalThis.addEventListener?.('beforeunload', (e) => {
      if (this.session.hasLease && (this.st.push || this.st.phase === 'scanning' || (this.st.assembly && !this.st.assembly.done))) {
        e.preventDefault();
        e.returnValue = '';
      }
    });
    $('csv').addEventListener('click', () => downloadCsv(this.st.trace));
    $('rec-refresh').addEventListener('click', () => this.records.refresh());
  }

  /**
   * Shows or hides the 3D companion view (remembered); hidden, it costs nothing per frame, and
   * three.js is loaded only when it is first shown. Resolves once it is shown.
   */
  show3d(on) {
    const $ = this.$;
    $('toggle-3d').setAttribute('aria-pressed', String(on));
    $('viewport').hidden = !on;
    $('layout').classList.toggle('with3d', on);
    try {
      localStorage.setItem('nanopush.3d', on ? '1' : '0');
    } catch {
      // (storage refused: not remembered)
    }
    return this.view.setShown(on).catch((e) => {
      // (The server away: its module cannot be fetched now; the button tries again.)
      this.log.log(`the 3D view could not load (${e.message}); try again once the server is back`, 'bad');
      this.show3d(false);
    });
  }

  /** Starts the page: the frame loop, the scene, the records and the connection. */
  start() {
    let on = false;
    try {
      on = localStorage.getItem('nanopush.3d') === '1';
    } catch {
      // (storage refused)
    }
    this.show3d(on);
    this.frames.start();
    this.toolbar.setExaggeration(1);
    this.render();
    this.loadScene();
    this.records.refresh();
    this.conn.connect();
  }

  render() {
    this.status.render(this.st);
    this.controls.render();
    this.assemble.render();
  }

  /** The live views: the tip (3D, readout, haptic panel) and the plots. */
  drawLive(parts) {
    const st = this.st;
    if (parts.has('tip')) {
      this.view.setTip(st.tip);
      this.map.tipMoved();
      this.tipTextFrame.mark();
      this.haptic.update(st.tip?.t, st.tip?.haptic);
      this.pushStatus.progressed();
    }
    if (parts.has('charts')) this.charts.update(st.trace);
  }

  onClose(ev, { wasOpen = true } = {}) {
    // (Called before the Session forgets what the server said: the lease, the push.)
    const { client, push } = this.st;
    const hadLease = this.session.hasLease;
    // The shutdown message was logged when it came: do not say it twice. A refused attempt to
    // reconnect is no news (the status bar counts the attempts): once every 2 s, it would push
    // everything else out of the log while the server is down.
    if (this.st.shutdown === null && wasOpen) this.log.log(closedText(ev), 'bad');
    // What the server said no longer holds: grey the live views, mark them "unknown".
    this.doc.body.classList.add('offline');
    this.$('offline').hidden = false;
    this.$('tipinfo').textContent = 'tip: unknown';
    if (push) {
      // The push it saw running: its outcome is unknown until the server is back.
      this.pushStatus.closed(client);
      const text = lostOnCloseText(push, hadLease);
      this.log.log(text, 'warn');
      this.log.announce(text);
      if (push.by === client && this.replies.latest('reply-push') !== undefined) this.replies.show('reply-push', 'unknown', 'push outcome unknown: disconnected');
    } else if (hadLease) {
      this.log.log(LEASE_LOST_ON_CLOSE, 'bad');
      this.log.announce(LEASE_LOST_ON_CLOSE);
    }
    // "lease taken" no longer holds.
    if (hadLease && this.replies.latest('reply-lease') !== undefined) this.replies.show('reply-lease', 'unknown', 'lease lost with the connection');
    queueMicrotask(() => {
      this.replies.closed(this.st.commands);
      this.controls.renderPush();
      this.map.invalidate();
    });
  }

  /** One server message: the Session applies it; its event goes to the parts it concerns. */
  onMessage(data) {
    const { st, log, controls } = this;
    const ev = this.session.apply(data);
    switch (ev.kind) {
      case 'welcome':
        this.conn.send(commands.subscribe(STREAMS));
        // The scene again only from a restarted server (it may run another); the first is
        // fetched at start.
        if (ev.restarted || !this.sceneLoading) this.loadScene();
        log.log(welcomeText(st));
        if (ev.restarted) this.onRestart();
        if (!st.lastRun) this.showLastFromHistory();
        break;
      case 'state':
        this.onState(ev);
        break;
      case 'telemetry':
        // Read: acknowledged (the newest, at most every 100 ms), so that the server keeps no
        // more frames in flight than this page takes in half a second (a busy page gets the
        // newest, not a backlog).
        if (st.tip.seq !== null) this.conn.ack(st.tip.seq);
        this.liveFrame.mark('tip', 'charts');
        if (st.tip.phase !== this.lastPhase) {
          this.lastPhase = st.tip.phase;
          this.statusFrame.mark();
        }
        return; // 60 Hz: drawn in the next animation frame, with whatever else changed
      case 'scan_start':
        this.scans.started();
        return;
      case 'scan_line':
        this.scans.line(ev);
        return;
      case 'scan_done':
        this.scans.done(ev);
        this.records.refresh();
        break;
      case 'push_started':
        log.log(pushStartedText(ev.push, st.client));
        for (const line of pushStrategy(ev.push)) log.log(line);
        for (const w of pushWarnings(ev.push)) log.log(w, 'warn');
        this.charts.restartFd(st.tip?.t ?? -Infinity);
        this.map.pushStarted();
        controls.renderPush();
        break;
      case 'run_done': {
        const r = ev.run;
        const text = describeRun(r);
        log.log(text, runClass(r));
        const short = describeRun(r, { record: false });
        controls.showLastRun(r, short);
        this.map.invalidate();
        log.announce(short);
        this.records.noteRun(r);
        this.view.updateParticles(st.particles, controls.selected);
        controls.particlesMoved(); // a scan centred on the particle follows it
        controls.renderPush();
        this.scans.renderStale();
        this.records.refresh();
        break;
      }
      case 'reply':
        this.replies.replied(ev);
        if (!ev.ok) log.log(replyErrorText(ev, st.lastError), 'bad');
        break;
      case 'assembly': {
        const line = assemblyLogLine(ev, st.client);
        if (line) log.log(line.text, line.cls);
        if (line && (ev.what === 'done' || ev.what === 'planned')) log.announce(line.text);
        this.assemble.assemblyChanged(ev);
        // The frame it was planned on: the map shows what the plan is drawn over.
        if (ev.what === 'planned' && ev.assembly.frame) this.scans.openRecord(ev.assembly.frame);
        if (ev.what === 'done' && ev.assembly.done.record) {
          this.scans.openAssemblyFrame(ev.assembly.done.record);
          this.records.refresh();
        }
        break;
      }
      case 'lagged':
        break;
      case 'lease': {
        const n = leaseNote(ev, st);
        log.log(n.text, n.cls);
        if (n.announce) log.announce(n.announce);
        controls.renderPush();
        break;
      }
      case 'shutdown':
        log.log(`server shutting down: ${st.shutdown}`, 'bad');
        log.announce(`server shutting down: ${st.shutdown}`);
        break;
      case 'error':
        log.log(`${st.lastError.code}: ${st.lastError.message}`, 'bad');
        break;
      default:
        break;
    }
    this.render();
  }

  /**
   * A page that has seen no push yet (just opened, reloaded) shows the newest recorded run, with
   * its time: a lease holder who reloaded mid-push reads how that push ended.
   */
  async showLastFromHistory() {
    if (this.demo) return;
    const version = this.pushStatus.version; // anything shown meanwhile wins
    try {
      const r = await fetch(apiUrl('/api/runs', this.loc));
      if (!r.ok) return;
      const [run] = await r.json();
      if (!run || this.st.lastRun || this.st.push || this.pushStatus.version !== version) return;
      this.pushStatus.showRun(`last recorded run (${clockTime(run.modified * 1000)}): ${describeRun(run, { record: false })}`, runClass(run));
    } catch {
      // (no history: nothing to show)
    }
  }

  /** The server restarted while this page was away: say so; what it showed is gone. */
  onRestart() {
    const text = restartText(this.st.startedUnixMs);
    this.log.log(text, 'warn');
    this.log.announce(text);
    this.pushStatus.clearRun();
    this.st.lastRun = null; // the previous server's: the history says what it recorded
    this.charts.restartFd(-Infinity);
  }

  /**
   * A push ran when the connection closed and its end was not seen: read its outcome from its
   * record in the run history (that server run's, that run number), else say it is unknown.
   */
  async settleLostPush() {
    const st = this.st;
    const lost = st.lostPush;
    st.lostPush = null;
    if (!lost || st.push) return; // (still running: the state says so)
    this.pushStatus.showRun(`push of #${lost.particle}: reading its outcome from the run history…`, 'unknown');
    let run = null;
    try {
      const r = await fetch(apiUrl('/api/runs', this.loc));
      if (r.ok) run = lostPushRun(await r.json(), lost);
    } catch {
      // (no history: unknown)
    }
    const text = lostPushText(lost, { restarted: st.restarted, run });
    const cls = run ? runClass(run) : 'unknown';
    this.log.log(text, cls === 'unknown' ? 'warn' : cls);
    this.log.announce(text);
    this.pushStatus.showRun(text, cls);
    if (this.replies.latest('reply-push') !== undefined && this.$('reply-push').classList.contains('unknown')) {
      this.replies.show('reply-push', cls, run ? pushEndedText(run) : 'push outcome unknown', this.$('reply-push').title);
    }
    this.records.refresh();
  }

  /** The server's `state`: particles, lease, phase, the push running and the latest scan. */
  onState(ev) {
    const st = this.st;
    if (st.lostPush) this.settleLostPush();
    this.view.updateParticles(st.particles, this.controls.selected);
    this.controls.particlesMoved();
    if (st.tip) this.liveFrame.mark('tip');
    this.scans.stateChanged(ev);
    if (ev.assemblyChanged) this.assemble.assemblyChanged();
    this.controls.renderPush();
    this.scans.renderStale();
    this.log.log(stateText(st));
  }

  /** Fetches the scene (once at start, again from a restarted server) and applies it. */
  loadScene() {
    this.sceneLoading = this.fetchScene();
    return this.sceneLoading;
  }

  async fetchScene() {
    if (this.demo) {
      const { demoScene } = await import('./demo.js');
      this.applyScene(demoScene());
      return;
    }
    try {
      const r = await fetch(apiUrl('/api/scene', this.loc));
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      this.applyScene(await r.json());
    } catch (e) {
      this.sceneLoading = null; // (tried again with the next welcome)
      this.log.log(`could not load /api/scene: ${e.message}`, 'bad');
    }
  }

  applyScene(scene) {
    this.session.setScene(scene);
    this.charts.setSetPoint(setPointForceN(scene));
    this.$('scene-name').textContent = scene.name ? `· ${scene.name}` : '';
    this.view.setStage(this.st.stageRange * 1e6);
    this.image2d.setStage(this.st.stageRange);
    this.controls.applyScene(scene);
    this.assemble.applyScene();
  }
}

/** Builds and starts the operator page (src/main.js); `window.nanopush` is for tests and the curious. */
export function start() {
  const app = new App(document, location);
  app.start();
  const { session, image2d, map, charts, haptic, frames } = app;
  // `view`: the 3D view once opened (three.js loaded), else its host.
  window.nanopush = { session, get view() { return app.view.view ?? app.view; }, image2d, map, charts, haptic, frames, app };
  return app;
}
