// The operator's controls: the lease, push (by distance or to a target picked in the 3D view,
// with a preview), scan, Stop (on the pointer's press; Esc too) and the haptic handle; each
// enabled only when the Session allows it (the lease, the instrument's offers), with the reason
// as a tooltip; the replies shown by command id; the running push (everyone's view of it). What
// the forms mean (commands, the preview, texts) is pure (Node tests); Controls binds them to the
// page.
import { commands } from './wire.js';
import { controlState, runClass } from './session.js';
import { formatLength } from './format.js';
import { isSimulated, replyWords, replyTitle } from './words.js';

/** Where each command's reply shows (an `<output>` id). */
export const REPLY_OUTPUT = Object.freeze({ take_lease: 'reply-lease', release_lease: 'reply-lease', push: 'reply-push', scan: 'reply-scan', assemble: 'reply-assemble', stop: 'reply-stop', haptic: 'reply-haptic' });

/** A form field's number: undefined when empty (the server's default), else Number (NaN for junk). */
export function readNumber(text) {
  const v = text.trim();
  return v === '' ? undefined : Number(v);
}

/** A command's reply in its output, in words: `lease taken`, `refused: push needs the lease`. */
export function replyText(c) {
  return replyWords(c);
}

/**
 * The push's reply once the push ended (`run_done`): its outcome in a word or two; the last run's
 * line says the whole story.
 */
export function pushEndedText(run) {
  const o = run.outcome;
  return o === 'ok' ? 'push ended: ok' : o === 'stopped' ? 'push ended: stopped' : o === 'missed' ? 'push ended: missed the target' : `push ended: failed (${String(o).replace(/_/g, ' ')})`;
}

/** A particle in the push form's list: `#1 gold-coated latex (r 500 nm)`. */
export function particleLabel(p) {
  return `#${p.id}${p.material ? ` ${p.material}` : ''} (r ${formatLength(p.radius)})`;
}

/** A target picked in the 3D view (µm), kept on the stage [0, rangeUm]². */
export function clampTarget(xUm, yUm, rangeUm) {
  return [Math.min(rangeUm, Math.max(0, xUm)), Math.min(rangeUm, Math.max(0, yUm))];
}

/**
 * The push form's command (throws a RangeError naming a field out of range).
 * @param {'by' | 'to'} mode
 * @param {number} particle
 * @param {{distance?: number, direction?: number, toX?: number, toY?: number, tolerance?: number}} v
 *   the fields (µm, °; the tolerance in nm, the server's default when left empty)
 * @param {number} rangeUm the stage's range
 * @param {{default: number, min: number, max: number} | null} [tolerance] the tolerance's range
 *   as the server checks it (its `welcome`)
 */
export function pushCommand(mode, particle, v, rangeUm, tolerance) {
  const m = mode === 'by'
    ? commands.pushBy(particle, v.distance, v.direction)
    : commands.pushTo(particle, v.toX, v.toY, undefined, rangeUm);
  return commands.withTolerance(m, v.tolerance, tolerance);
}

/**
 * The tolerance field's attributes from the tolerance the server checks (its `welcome`): its
 * range, and its default as the value the form starts at; all empty before the server said
 * (or when it says none), which leaves the tolerance to the server.
 * @param {{default: number, min: number, max: number} | null} t
 */
export function toleranceField(t) {
  return t ? { min: String(t.min), max: String(t.max), value: String(t.default) } : { min: '', max: '', value: '' };
}

/**
 * The form's push preview in the 3D view: `target` {x, y} (µm) and `preview` {from {x, y, z},
 * deg, lengthUm}, each null when not drawn. Only the lease holder's own, and only while no push
 * runs (viewers see the operator's commanded path instead, from `push_started` / `state`).
 * @param {{x: number, y: number, radius: number} | undefined} p the selected particle (m)
 */
export function pushPreview(p, { running, hasLease, mode, distance, direction, toX, toY }) {
  const none = { target: null, preview: null };
  if (!p || running || !hasLease) return none;
  const from = { x: p.x * 1e6, y: p.y * 1e6, z: p.radius * 1e6 };
  if (mode === 'by') return { target: null, preview: { from, deg: direction ?? 0, lengthUm: distance ?? 0 } };
  if (toX === undefined || toY === undefined) return none;
  const dx = toX - from.x;
  const dy = toY - from.y;
  return { target: { x: toX, y: toY }, preview: { from, deg: (Math.atan2(dy, dx) * 180) / Math.PI, lengthUm: Math.hypot(dx, dy) } };
}

/**
 * The preview on the map: the selected particle's path from where it is to where the push would
 * leave it (m), or null. 0° is +x (right on the map), 90° is +y (up).
 */
export function previewLine(preview) {
  if (!preview || !(preview.lengthUm > 0)) return null;
  const a = (preview.deg * Math.PI) / 180;
  const { x, y } = preview.from;
  return { from: [x * 1e-6, y * 1e-6], to: [(x + preview.lengthUm * Math.cos(a)) * 1e-6, (y + preview.lengthUm * Math.sin(a)) * 1e-6] };
}

/**
 * The note under Stop: why Push and Scan cannot go now, each reason once (the lease's is both's;
 * a real controller's differ); '' when both can.
 */
export function whyText(c) {
  return [...new Set([c.push, c.scan].filter((s) => !s.enabled).map((s) => s.why))].join('. ');
}

/**
 * Why Stop cannot act now, said when it is pressed anyway (a click, Esc): without a connection
 * it cannot reach the server, and the server acts on its own (the lease holder gone, its push
 * stopped); else the reason the controls give.
 */
export function stopRefusedText(state, why) {
  if (state.connection !== 'open') {
    return 'Stop cannot reach the server (not connected). A running server stops a push whose lease holder is gone on its own.';
  }
  return `Stop not sent: ${why.charAt(0).toLowerCase()}${why.slice(1)}.`;
}

/** Whether the server drives a real controller (its scans take the controller's frame). */
export function realController(st) {
  return Boolean(st.instrument) && !isSimulated(st.instrument);
}

/**
 * The scan form's start from the scene's own scan, made small enough that the smallest particle
 * spans at least 2 pixels (a 14 nm particle is not seen in a 50 µm, 256 px scan).
 */
export function scanFormDefaults(scene) {
  const out = {};
  if (!scene.scan) return out;
  const pixels = Number.isFinite(scene.scan.pixels) ? Math.min(512, Math.max(8, scene.scan.pixels)) : null;
  if (pixels !== null) out.pixels = String(pixels);
  if (Number.isFinite(scene.scan.size_um)) {
    let size = scene.scan.size_um;
    const radii = (scene.particles ?? []).map((p) => p.radius_nm).filter((r) => Number.isFinite(r) && r > 0);
    if (radii.length && pixels !== null) {
      const most = (2 * Math.min(...radii) * 1e-3 * pixels) / 2; // µm
      if (most < size) size = Number(most.toPrecision(2));
    }
    out.size = String(size);
  }
  return out;
}

/** The replies of commands, each in its output, and only the latest command's per output. */
export class Replies {
  /** @param {(id: string) => HTMLElement} $ */
  constructor($) {
    this.$ = $;
    this.lastIdByOutput = new Map(); // output element id → latest command id shown there
  }

  /** A command is about to go (it has its id). */
  sent(m) {
    const out = REPLY_OUTPUT[m.type];
    if (out) {
      this.lastIdByOutput.set(out, m.id);
      this.show(out, 'pending', replyWords({ status: 'pending' }), replyTitle(m));
    }
  }

  /** A `reply` event of the Session. */
  replied(ev) {
    if (!ev.command) return;
    const out = REPLY_OUTPUT[ev.command.type];
    if (out && this.lastIdByOutput.get(out) === ev.id) this.show(out, ev.command.status, replyText(ev.command), replyTitle(ev.command));
  }

  /** The connection closed: a command still waiting for its reply will get none. */
  closed(commandsById) {
    for (const [out, id] of this.lastIdByOutput) {
      const c = commandsById.get(id);
      if (c && c.code === 'disconnected') this.show(out, 'error', replyText(c), replyTitle(c));
    }
  }

  /** The latest command sent to output `id` (its Session record's id), or undefined. */
  latest(id) {
    return this.lastIdByOutput.get(id);
  }

  show(id, status, text, title = '') {
    const el = this.$(id);
    el.className = `reply ${status}`;
    el.textContent = text;
    el.title = title;
  }
}

export class Controls {
  /**
   * @param {(id: string) => HTMLElement} $ the page's elements by id
   * @param {Document} doc
   * @param {object} deps
   * @param {import('./session.js').Session} deps.session
   * @param {import('./view3d.js').View3D} deps.view
   * @param {Replies} deps.replies
   * @param {(msg: object) => object | null} deps.send sends a command (Connection.send)
   * @param {() => void} deps.onScanRequested the operator asked for a scan
   */
  constructor($, doc, { session, view, map = () => null, status, replies, send, onScanRequested, announce = () => {} }) {
    this.$ = $;
    this.doc = doc;
    this.session = session;
    this.st = session.state;
    this.view = view;
    this.map = map;
    this.replies = replies;
    this.status = status;
    this.announce = announce;
    this.send = send;
    this.onScanRequested = onScanRequested;
    this.selected = null; // the particle to push (id)
    this.scanCentreTouched = false; // the operator typed a scan centre: keep it
    this.scanFormTouched = false; // the operator typed a scan size or pixels: keep them
    this.toleranceTouched = false; // the operator typed a tolerance: keep it
    this.toleranceShown = undefined; // the server's tolerance the field was last set from
    this.stopPressed = false; // Stop went on the pointer's press: ignore the click that follows
    this.bind();
  }

  num(id) {
    return readNumber(this.$(id).value);
  }

  mode() {
    return this.doc.querySelector('input[name=mode]:checked').value;
  }

  setMode(m) {
    this.$('by-fields').hidden = m !== 'by';
    this.$('to-fields').hidden = m !== 'to';
  }

  /** Sends what `build` makes; a builder's range error shows in the output instead. */
  guarded(out, build) {
    try {
      this.send(build());
    } catch (e) {
      this.replies.show(out, 'error', `not sent: ${e.message}`);
    }
  }

  /** The tolerance field as the server checks the tolerance, once per change of what it said. */
  applyTolerance(t) {
    if (t === this.toleranceShown) return;
    this.toleranceShown = t;
    const el = this.$('tolerance');
    const f = toleranceField(t);
    el.min = f.min;
    el.max = f.max;
    if (!this.toleranceTouched) el.value = f.value;
  }

  /** Enables what the Session allows, with the reason as a tooltip. */
  render() {
    const $ = this.$;
    this.applyTolerance(this.st.pushTolerance);
    const c = controlState(this.st);
    const focused = this.doc.activeElement;
    const set = (el, s) => {
      el.disabled = !s.enabled;
      el.title = s.why;
    };
    // Viewers get no forms they cannot use: the reason says how to command instead.
    const viewer = this.st.role === 'viewer';
    if (this.st.role) this.lastRole = this.st.role; // the role before a disconnection
    $('push-form').hidden = viewer;
    $('scan-form').hidden = viewer;
    $('hap-fs').hidden = viewer;
    set($('take-lease'), c.takeLease);
    set($('release-lease'), c.releaseLease);
    set($('push-fs'), c.push);
    set($('scan-fs'), c.scan);
    // A real controller scans its own frame and pixels (what its software shows): the square's
    // fields are the simulated AFM's.
    const real = realController(this.st);
    for (const id of ['scan-x', 'scan-y', 'scan-size', 'scan-px', 'scan-centre']) {
      $(id).disabled = real;
      $(id).title = real ? 'On a real controller a scan takes the controller\'s own frame and pixels' : '';
    }
    // Stop stays pressable (a careless press, Esc) and says why it cannot act: aria-disabled.
    const stop = $('stop-btn');
    stop.setAttribute('aria-disabled', String(!c.stop.enabled));
    stop.title = c.stop.why;
    this.stopWhy = c.stop.enabled ? null : c.stop.why;
    set($('hap-fs'), c.haptic);
    set($('hap-engage'), c.hapticEngage);
    // Buttons inside a disabled fieldset: give them the reason as a tooltip too.
    $('push-btn').title = c.push.why;
    $('scan-btn').title = c.scan.why;
    $('why').textContent = whyText(c);
    // A button that took the focus and is now disabled (Take lease, once taken) would drop it to
    // the page: hand it to its counterpart.
    if (focused && focused.disabled && focused !== this.doc.body) {
      const next = { 'take-lease': 'release-lease', 'release-lease': 'take-lease', 'hap-engage': 'hap-release' }[focused.id];
      const n = next && $(next);
      if (n && !n.disabled) n.focus();
      else this.stopWhy ? this.doc.querySelector('.map-svg')?.focus() : $('stop-btn').focus();
    }
  }

  /** The push running (everyone's view of it) or, for the lease holder, the form's preview. */
  renderPush() {
    const { st, view } = this;
    const p = st.push;
    this.map()?.invalidate();
    if (p) {
      view.setPushPath(p.path);
      view.setPreview(null);
      view.setTarget(null);
    } else {
      view.setPushPath(null);
      this.updatePreview();
    }
    this.status.render();
  }

  updatePreview() {
    const { st, view } = this;
    const p = st.particles.find((q) => q.id === this.selected);
    const { target, preview } = pushPreview(p, {
      running: !!st.push, hasLease: this.session.hasLease, mode: this.mode(),
      distance: this.num('distance'), direction: this.num('direction'), toX: this.num('to-x'), toY: this.num('to-y'),
    });
    if (target) view.setTarget(target.x, target.y);
    else view.setTarget(null);
    this.map()?.setTarget(target ? target.x : null, target ? target.y : null);
    if (preview) view.setPreview(preview.from, preview.deg, preview.lengthUm);
    else view.setPreview(null);
    this.map()?.setPreview(previewLine(preview));
  }

  /** The scene's particles and stage in the forms (and the 3D view's particles). */
  applyScene(scene) {
    const { $, st, view } = this;
    const range = st.stageRange * 1e6;
    for (const id of ['to-x', 'to-y', 'scan-x', 'scan-y']) $(id).max = String(range);
    const sel = $('particle');
    sel.replaceChildren(...st.particles.map((p) => {
      const o = this.doc.createElement('option');
      o.value = String(p.id);
      o.textContent = particleLabel(p);
      return o;
    }));
    if (!st.particles.some((p) => p.id === this.selected)) this.selected = st.particles[0]?.id ?? null;
    if (this.selected !== null) sel.value = String(this.selected);
    view.setParticles(st.particles, this.selected);
    if (!st.scan) view.frameStage();
    if ($('scan-x').value === '') this.centreScanOnParticle();
    if (!this.scanFormTouched) {
      const d = scanFormDefaults(scene);
      if (d.size !== undefined) $('scan-size').value = d.size;
      if (d.pixels !== undefined) $('scan-px').value = d.pixels;
    }
    this.renderPush();
  }

  /** The server's `state` moved the particles: a scan centred on the selected one follows it. */
  particlesMoved() {
    if (this.selected !== null && this.$('scan-x').value !== '' && !this.scanCentreTouched) this.centreScanOnParticle();
  }

  selectParticle(id) {
    this.selected = id;
    this.$('particle').value = String(id);
    this.view.updateParticles(this.st.particles, this.selected);
    this.renderPush();
  }

  /** A finished push's outcome under Stop, in its colour; the push's reply says it in a word. */
  showLastRun(run, text) {
    this.status.showRun(text, runClass(run));
    const out = this.$('reply-push');
    if (out.textContent) this.replies.show('reply-push', runClass(run), pushEndedText(run), out.title);
  }

  /** Stop pressed (the button, Esc): sent when it may be; else why not, said and announced. */
  stop() {
    if (!this.stopWhy) {
      this.guarded('reply-stop', () => commands.stop());
      return;
    }
    const text = stopRefusedText(this.st, this.stopWhy);
    this.replies.show('reply-stop', 'error', text);
    this.announce(text);
  }

  /** A point picked in the 3D view: the push target. */
  pickTarget(xUm, yUm) {
    const [x, y] = clampTarget(xUm, yUm, this.st.stageRange * 1e6);
    this.$('to-x').value = x.toFixed(2);
    this.$('to-y').value = y.toFixed(2);
    this.doc.querySelector('input[name=mode][value=to]').checked = true;
    this.setMode('to');
    this.updatePreview();
  }

  centreScanOnParticle() {
    const p = this.st.particles.find((q) => q.id === this.selected);
    if (!p) return;
    this.$('scan-x').value = (p.x * 1e6).toFixed(2);
    this.$('scan-y').value = (p.y * 1e6).toFixed(2);
  }

  bind() {
    const { $, doc } = this;
    $('take-lease').addEventListener('click', () => this.guarded('reply-lease', () => commands.takeLease()));
    $('release-lease').addEventListener('click', () => this.guarded('reply-lease', () => commands.releaseLease()));
    // Stop goes on the pointer's press, not its release (a click): one event sooner. The click
    // that follows is then ignored; a keyboard's Enter or Space still clicks.
    $('stop-btn').addEventListener('pointerdown', (e) => {
      if (e.button !== 0) return;
      this.stopPressed = true;
      this.stop();
    });
    $('stop-btn').addEventListener('click', () => {
      if (this.stopPressed) {
        this.stopPressed = false;
        return;
      }
      this.stop();
    });
    $('push-form').addEventListener('submit', (e) => {
      e.preventDefault();
      const particle = Number($('particle').value);
      this.guarded('reply-push', () => pushCommand(this.mode(), particle,
        { distance: this.num('distance'), direction: this.num('direction'), toX: this.num('to-x'), toY: this.num('to-y'), tolerance: this.num('tolerance') },
        this.st.stageRange * 1e6, this.st.pushTolerance));
    });
    $('scan-form').addEventListener('submit', (e) => {
      e.preventDefault();
      this.onScanRequested();
      this.guarded('reply-scan', () => (realController(this.st)
        ? commands.scan({})
        : commands.scan({ centreXUm: this.num('scan-x'), centreYUm: this.num('scan-y'), sizeUm: this.num('scan-size'), pixels: this.num('scan-px') })));
    });
    $('scan-centre').addEventListener('click', () => {
      this.scanCentreTouched = false;
      this.centreScanOnParticle();
    });
    $('particle').addEventListener('change', () => this.selectParticle(Number($('particle').value)));
    for (const r of doc.querySelectorAll('input[name=mode]')) r.addEventListener('change', () => {
      this.setMode(this.mode());
      this.updatePreview();
    });
    for (const id of ['distance', 'direction', 'to-x', 'to-y']) $(id).addEventListener('input', () => this.updatePreview());
    for (const a of ['engage', 'release', 'recenter']) $(`hap-${a}`).addEventListener('click', () => this.guarded('reply-haptic', () => commands.haptic(a)));
    $('hap-scale').addEventListener('click', () => this.guarded('reply-haptic', () => commands.haptic('scale', { nmPerMm: this.num('hap-nm'), pullOffAtHandN: this.num('hap-po') })));
    for (const id of ['scan-x', 'scan-y']) $(id).addEventListener('input', () => { this.scanCentreTouched = true; });
    for (const id of ['hap-nm', 'hap-po']) $(id).addEventListener('input', () => { delete $(id).dataset.fromServer; });
    for (const id of ['scan-size', 'scan-px']) $(id).addEventListener('input', () => { this.scanFormTouched = true; });
    $('tolerance').addEventListener('input', () => { this.toleranceTouched = true; });
    // Esc is Stop wherever the focus is; an operator page says why when Stop cannot act.
    doc.addEventListener('keydown', (e) => {
      if (e.key !== 'Escape' || e.defaultPrevented) return;
      if (this.stopWhy && (this.st.role ?? this.lastRole) !== 'operator') return;
      e.preventDefault();
      this.stop();
    });
  }
}
