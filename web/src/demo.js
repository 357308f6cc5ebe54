// `?demo`: a stand-in for the server's WebSocket that speaks the same protocol (JSON messages
// and binary scan-line frames made by encodeScanLine), so the page can be shown and tried with
// no server. A toy: particles are spheres on a slightly tilted plane, pushes move them in a
// straight line. Not a simulation of anything in the paper.
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
