// `?demo`: a stand-in for the server's WebSocket that speaks the same protocol (JSON messages
// and binary scan-line frames made by encodeScanLine), so the page can be shown and tried with
// no server. A toy: particles are spheres on a slightly tilted plane, pushes move them in a
// straight line, an assembly sends each site the nearest particle left. Not a simulation of
// anything in the paper.
import { encodeScanLine } from './wire.js';

export function demoScene() {
  return {
    name: 'demo (no server)',
    particles: [
      { id: 1, material: 'gold-coated latex', radius_nm: 500, x_um: 50, y_um: 50 },
      { id: 2, material: 'gold-coated latex', radius_nm: 500, x_um: 53, y_um: 47.5 },
      { id: 3, material: 'gold-coated latex', radius_nm: 500, x_um: 46.5, y_um: 52 },
    ],
    stage: { range_um: 100 },
    push: { speed_um_per_s: 2 },
  };
}

export class DemoSocket {
  constructor(url, role = 'operator') {
    this.url = url;
    this.role = role === 'viewer' ? 'viewer' : 'operator';
    this.readyState = 0;
    this.binaryType = 'arraybuffer';
    this.t0 = performance.now();
    this.client = 7;
    this.lease = null;
    this.particles = demoScene().particles.map((p) => ({ id: p.id, r: p.radius_nm * 1e-9, x: p.x_um * 1e-6, y: p.y_um * 1e-6 }));
    this.tip = [50e-6, 50e-6, 2e-6];
    this.phase = 'idle';
    this.job = null;
    this.scanId = 0;
    this.estimate = null;
    setTimeout(() => {
      this.readyState = 1;
      this.onopen?.({});
      this.emit({ type: 'welcome', version: 1, client: this.client, role: this.role, lease: null, scene: 'demo', tick_hz: 1000 });
      this.timer = setInterval(() => this.tick(), 1000 / 30);
    }, 200);
  }

  emit(m) {
    this.onmessage?.({ data: JSON.stringify(m) });
  }

  now() {
    return (performance.now() - this.t0) / 1000;
  }

  close() {
    clearInterval(this.timer);
    this.readyState = 3;
    this.onclose?.({ code: 1000, reason: '' });
  }

  height(x, y) {
    let h = 0.003 * (x - 50e-6) + 2e-9 * Math.sin(x / 3e-6) * Math.cos(y / 4e-6);
    for (const p of this.particles) {
      const d2 = (x - p.x) ** 2 + (y - p.y) ** 2;
      if (d2 < p.r * p.r) h = Math.max(h, p.r + Math.sqrt(p.r * p.r - d2));
    }
    return h;
  }

  send(text) {
    const m = JSON.parse(text);
    const ok = () => this.emit({ type: 'ok', id: m.id ?? null });
    const err = (code, message) => this.emit({ type: 'error', id: m.id ?? null, code, message });
    if (m.type === 'ack') return; // not answered, as the server does
    if (m.type === 'subscribe' || m.type === 'ping') return ok();
    if (this.role !== 'operator') return err('forbidden', 'viewers cannot command');
    if (m.type === 'take_lease') {
      ok();
      this.lease = this.client;
      return this.emit({ type: 'lease', holder: this.lease });
    }
    if (this.lease !== this.client) return err('no_lease', `${m.type} needs the lease`);
    if (m.type === 'release_lease') {
      ok();
      this.lease = null;
      return this.emit({ type: 'lease', holder: null });
    }
    if (m.type === 'stop') {
      ok();
      if (this.job?.kind === 'push') this.finishPush('stopped', 'stopped by the operator');
      this.job = null;
      this.phase = 'idle';
      if (this.asm) this.endAssembly('stopped', 'stopped: stop requested by the operator');
      return;
    }
    if (this.job) return err('busy', `a ${this.job.kind} runs; stop it first`);
    if (m.type === 'scan') {
      const size = (m.size_um ?? 10) * 1e-6;
      const n = m.pixels ?? 128;
      const cx = (m.centre_x_um ?? 50) * 1e-6;
      const cy = (m.centre_y_um ?? 50) * 1e-6;
      ok();
      this.scanId++;
      const s = { kind: 'scan', id: this.scanId, n, x0: cx - size / 2, y0: cy - size / 2, size, line: 0 };
      this.job = s;
      this.phase = 'scanning';
      this.emit({ type: 'scan_start', scan: s.id, xres: n, yres: n, x_offset: s.x0, y_offset: s.y0, x_real: size, y_real: size });
      return;
    }
    if (m.type === 'assemble') {
      if (this.asm) return err('busy', 'an assembly runs; stop it first');
      ok();
      return this.startAssembly(m);
    }
    if (m.type === 'push') {
      const p = this.particles.find((q) => q.id === m.particle);
      if (!p) return err('unknown_particle', `no particle ${m.particle}`);
      let tx;
      let ty;
      if (m.distance_um !== undefined) {
        const a = ((m.direction_deg ?? 0) * Math.PI) / 180;
        tx = p.x + m.distance_um * 1e-6 * Math.cos(a);
        ty = p.y + m.distance_um * 1e-6 * Math.sin(a);
      } else {
        tx = m.to_x_um * 1e-6;
        ty = m.to_y_um * 1e-6;
      }
      ok();
      this.job = { kind: 'push', p, tx, ty, t: 0 };
      this.phase = 'approach';
      return;
    }
    return err('malformed', `unknown type ${m.type}`);
  }

  finishPush(outcome, failure) {
    const p = this.job.p;
    this.emit({ type: 'run_done', particle: p.id, outcome, failure, estimate: [p.x, p.y], record: null });
    this.estimate = null;
    if (this.asm && outcome === 'ok') setTimeout(() => this.nextMove(), 300);
  }

  /**
   * An `assemble` as the toy does it: each site takes the nearest particle left, pushed in a
   * straight line; no scans, no routing around the others, no re-planning worth the name.
   */
  startAssembly(m) {
    const tol = (m.tolerance_nm ?? 25) * 1e-9;
    const sites = m.sites.map((q) => ({ target: [q.x_um * 1e-6, q.y_um * 1e-6], tolerance: tol }));
    const map = this.particles.map((p) => ({ x: p.x, y: p.y, radius: p.r }));
    const free = new Set(map.keys());
    const plan = { map, sites: [], moves: [] };
    for (const [i, s] of sites.entries()) {
      let best = null;
      for (const k of free) if (best === null || Math.hypot(map[k].x - s.target[0], map[k].y - s.target[1]) < Math.hypot(map[best].x - s.target[0], map[best].y - s.target[1])) best = k;
      if (best === null) {
        plan.sites.push({ state: 'open', particle: null, status: 'unreachable', reason: 'no particle is left for it' });
        continue;
      }
      free.delete(best);
      plan.sites.push({ state: 'planned', particle: best });
      const from = [map[best].x, map[best].y];
      plan.moves.push({ purpose: 'fill', site: i, particle: best, from, to: s.target, path: [from, s.target] });
    }
    this.asm = { id: (this.asm?.id ?? 0) + 1, sites, plan, made: [], filled: [], t0: performance.now(), pushTime: 0 };
    this.emit({ type: 'assembly_planned', assembly: this.asm.id, by: this.client, plan_only: !!m.plan_only, pattern: 'sites', sites, plan });
    if (m.plan_only) return this.endAssembly('planned', null);
    this.nextMove();
  }

  nextMove() {
    const a = this.asm;
    if (!a) return;
    const last = a.current;
    if (last) {
      const p = this.particles[last.particle];
      const error = Math.hypot(p.x - last.to[0], p.y - last.to[1]);
      a.made.push({ purpose: 'fill', site: last.site, particle: p.id, from: last.from, to: last.to, outcome: 'ok', error, pushes: 1, push_time: Math.hypot(last.to[0] - last.from[0], last.to[1] - last.from[1]) / 2e-6 });
      this.emit({ type: 'assembly_move_ended', assembly: a.id, number: a.made.length, made: a.made[a.made.length - 1] });
      a.filled.push(last.site);
      this.emit({ type: 'assembly_site_filled', assembly: a.id, site: last.site });
      a.plan.moves.shift();
      this.emit({ type: 'assembly_replanned', assembly: a.id, plan: a.plan });
    }
    a.current = a.plan.moves[0] ?? null;
    if (!a.current) return this.endAssembly(a.plan.sites.every((s) => s.state === 'planned') ? 'filled' : 'incomplete', null);
    const p = this.particles[a.current.particle];
    this.emit({ type: 'assembly_move_started', assembly: a.id, number: a.made.length + 1, of: a.made.length + a.plan.moves.length, planned: a.current, particle_id: p.id });
    this.emit({ type: 'push_started', particle: p.id, path: a.current.path, by: this.client });
    this.job = { kind: 'push', p, tx: a.current.to[0], ty: a.current.to[1], t: 0 };
    this.phase = 'approach';
  }

  endAssembly(outcome, reason) {
    const a = this.asm;
    this.asm = null;
    const summary = outcome === 'planned' ? null : {
      schema: 'nanopush.assembly', outcome, refusal: null, pattern: 'sites', moves: a.made, violations: [],
      wall_time: (performance.now() - a.t0) / 1000, push_time: a.made.reduce((t, m) => t + m.push_time, 0), scan_time: 0,
      sites: a.sites.map((s, i) => {
        const k = a.plan.sites[i].particle;
        const p = k === null ? null : this.particles[k];
        const filled = a.filled.includes(i);
        return { target: s.target, tolerance: s.tolerance, particle: p?.id ?? null, measured: p ? [p.x, p.y] : null, true_position: p ? [p.x, p.y] : null, error: p ? Math.hypot(p.x - s.target[0], p.y - s.target[1]) : null, status: filled ? 'filled' : k === null ? 'unreachable' : 'missed', reason: filled ? null : a.plan.sites[i].reason ?? 'stopped before its move' };
      }),
    };
    this.emit({ type: 'assembly_done', assembly: a.id, outcome, reason, summary, record: null });
  }

  tick() {
    const t = this.now();
    const j = this.job;
    let volts = -0.2 + 0.005 * Math.sin(t * 19);
    if (j?.kind === 'scan') {
      for (let k = 0; k < 3 && j.line < j.n; k++, j.line++) {
        const y = j.y0 + ((j.line + 0.5) * j.size) / j.n;
        const hs = new Float32Array(j.n);
        for (let i = 0; i < j.n; i++) hs[i] = this.height(j.x0 + ((i + 0.5) * j.size) / j.n, y);
        this.tip = [j.x0 + j.size * ((t * 0.7) % 1), y, this.height(this.tip[0], y) + 20e-9];
        this.onmessage?.({ data: encodeScanLine({ scan: j.id, line: j.line, xres: j.n, yres: j.n, y }, hs) });
      }
      if (j.line >= j.n) {
        this.emit({ type: 'scan_done', scan: j.id, record: null });
        this.job = null;
        this.phase = 'idle';
      }
    } else if (j?.kind === 'push') {
      const p = j.p;
      const dx = j.tx - p.x;
      const dy = j.ty - p.y;
      const d = Math.hypot(dx, dy);
      const step = 2e-6 / 30; // 2 µm/s
      const ux = d > 0 ? dx / d : 1;
      const uy = d > 0 ? dy / d : 0;
      this.phase = 'push';
      if (d <= step) {
        p.x = j.tx;
        p.y = j.ty;
        this.finishPush('ok', null);
        this.job = null;
        this.phase = 'idle';
      } else {
        p.x += ux * step;
        p.y += uy * step;
        volts = -1.2 - 0.3 * Math.sin(t * 7) + 0.05 * Math.random();
      }
      this.tip = [p.x - ux * p.r * 1.05, p.y - uy * p.r * 1.05, p.r * 0.6];
      this.estimate = [p.x, p.y];
    } else {
      this.tip = [this.tip[0], this.tip[1], 2e-6 + 20e-9 * Math.sin(t)];
    }
    this.emit({ type: 'telemetry', t, stage: this.tip, volts, phase: this.phase, estimate: this.job?.kind === 'push' ? this.estimate : null });
  }
}
