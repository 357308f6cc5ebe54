// The page's figures for docs/benchmarks.md ("The Nano Visulator in a browser
// (`node e2e/bench.js`)"), measured (not asserted): its transfer size (first load, gzip as
// served) and its frames with a 512² scan on screen at 1600×1000 (headless chromium, WebGL on
// SwiftShader), idle and during a push, with the height image as the live map (the default) and
// with the 3D companion view shown too: frames a second, the frame times' median, 95th percentile
// and worst, and where a push's frames go (a profile: the main thread's time by kind from the
// Performance domain, each view's draws from the page's frame loop, the JavaScript by bundle and
// function from a CPU profile); Stop, from the press to the frame that shows its reply, during a
// push (three presses). (The docs' screenshots: e2e/screenshots.js.)
//   cd web && node e2e/bench.js                                  one run of this page
//   cd web && node e2e/bench.js --before DIR --runs 3            this page against another
//     build (DIR: a web/ directory with its dist/), alternately, in one run: medians and ratios
import { existsSync } from 'node:fs';
import { join, resolve, basename } from 'node:path';
import { loadavg, cpus } from 'node:os';
import { startServer, launchBrowser, newPage, ready, timedStop, serverBin, ROOT, WEB } from './support.js';

const arg = (name) => {
  const i = process.argv.indexOf(name);
  return i > 0 ? process.argv[i + 1] : undefined;
};
const before = arg('--before');
const runs = Number(arg('--runs') ?? 1);

// The server an operator runs (`make run`: release) when it is built: a debug server's push
// takes a core of its own, which a 2-core machine's browser then lacks. $NANOPUSH_BIN wins.
const release = join(process.env.CARGO_TARGET_DIR ? resolve(ROOT, process.env.CARGO_TARGET_DIR) : join(ROOT, 'target'), 'release', 'nanopush');
if (!process.env.NANOPUSH_BIN && existsSync(release)) process.env.NANOPUSH_BIN = release;
console.log(`server: ${serverBin()}; ${cpus().length} cores, load average ${loadavg().map((l) => l.toFixed(2)).join(' ')}`);

const quantile = (xs, q) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : NaN;
};
const median = (xs) => quantile(xs, 0.5);

/** One run of the page served from `webDir`: its figures. */
async function benchOnce(webDir, label) {
  const srv = await startServer({ webDir });
  const browser = await launchBrowser();
  const out = { label };
  try {
    const page = await newPage(browser);
    const cdp = await page.context().newCDPSession(page);
    await cdp.send('Network.enable');
    await cdp.send('Network.setCacheDisabled', { cacheDisabled: true });
    await cdp.send('Performance.enable');
    let wire = 0;
    let files = 0;
    const decoded = new Map();
    cdp.on('Network.loadingFinished', (e) => {
      wire += e.encodedDataLength;
      files++;
    });
    cdp.on('Network.dataReceived', (e) => decoded.set(e.requestId, (decoded.get(e.requestId) ?? 0) + e.dataLength));
    await page.goto(srv.url, { waitUntil: 'networkidle' });
    await ready(page);
    const raw = [...decoded.values()].reduce((a, b) => a + b, 0);
    out.load = { files, wireKiB: wire / 1024, rawKiB: raw / 1024 };
    console.log(`[${label}] page load: ${files} requests, ${(wire / 1024).toFixed(0)} KiB on the wire (gzip), ${(raw / 1024).toFixed(0)} KiB uncompressed`);

    const metrics = async () => Object.fromEntries((await cdp.send('Performance.getMetrics')).metrics.map((m) => [m.name, m.value]));
    // Frames for `ms`: rAF timestamps (frames/s, frame times), each view's draws (count, ms),
    // the main thread's time by kind.
    const measure = async (ms, { profile = false } = {}) => {
      const m0 = await metrics();
      if (profile) {
        await cdp.send('Profiler.enable');
        await cdp.send('Profiler.setSamplingInterval', { interval: 500 });
        await cdp.send('Profiler.start');
      }
      const r = await page.evaluate((dur) => new Promise((res) => {
        const views = () => Object.fromEntries(window.nanopush.frames.views.map((v) => [v.name, { n: v.frames, ms: v.totalMs ?? NaN }]));
        const v0 = views();
        const ts = [];
        const t0 = performance.now();
        const f = (t) => {
          ts.push(t);
          if (performance.now() - t0 < dur) requestAnimationFrame(f);
          else {
            const v1 = views();
            const per = {};
            for (const [k, v] of Object.entries(v1)) per[k] = { n: v.n - (v0[k]?.n ?? 0), ms: v.ms - (v0[k]?.ms ?? 0) };
            const gaps = ts.slice(1).map((x, i) => x - ts[i]);
            res({ n: ts.length, span: ts.at(-1) - ts[0], gaps, per });
          }
        };
        requestAnimationFrame(f);
      }), ms);
      const m1 = await metrics();
      const d = (k) => ((m1[k] ?? 0) - (m0[k] ?? 0)) * 1000;
      r.fps = ((r.n - 1) * 1000) / r.span;
      r.p50 = median(r.gaps);
      r.p95 = quantile(r.gaps, 0.95);
      r.max = Math.max(...r.gaps);
      r.main = { task: d('TaskDuration'), script: d('ScriptDuration'), layout: d('LayoutDuration'), style: d('RecalcStyleDuration'), wall: r.span };
      if (profile) {
        const { profile: p } = await cdp.send('Profiler.stop');
        r.js = summarize(p);
      }
      return r;
    };
    await page.click('#take-lease');
    await page.waitForFunction(() => window.nanopush.session.hasLease);
    await page.fill('#scan-size', '16');
    await page.fill('#scan-px', '512');
    await page.click('#scan-btn');
    await page.waitForFunction(() => window.nanopush.session.state.scan?.done, null, { timeout: 60000 });
    await page.waitForTimeout(1000);
    const duringPush = async (dir, opts) => {
      await page.check('input[name=mode][value=by]');
      await page.fill('#distance', '6');
      await page.fill('#direction', dir);
      await page.click('#push-btn');
      await page.waitForFunction(() => !['idle', 'scanning', 'preparing'].includes(window.nanopush.session.state.phase), null, { timeout: 30000 });
      await page.waitForTimeout(1000);
      const r = await measure(4000, opts);
      await page.waitForFunction(() => window.nanopush.session.state.phase === 'idle', null, { timeout: 60000 });
      return r;
    };
    // The default: the height image as the live map, the 3D view hidden.
    out.idle = await measure(3000);
    out.push = await duringPush('180');
    // With the 3D companion shown beside it.
    await page.click('#toggle-3d');
    await page.waitForFunction(() => window.nanopush.view.frames > 0, null, { timeout: 30000 });
    await page.waitForTimeout(1000);
    out.idle3 = await measure(3000);
    out.push3 = await duringPush('0', { profile: true });
    for (const k of ['idle', 'push', 'idle3', 'push3']) console.log(`[${label}] ${k}: ${line(out[k])}`);
    console.log(`[${label}] where a push's frames go (3D view shown): ${where(out.push3)}`);
    await page.click('#toggle-3d');
    const stops = [];
    for (let k = 0; k < 3; k++) {
      const running = await page.evaluate(() => !['idle', 'scanning', 'preparing'].includes(window.nanopush.session.state.phase));
      if (!running) {
        await page.fill('#direction', k % 2 ? '0' : '180');
        await page.click('#push-btn');
        await page.waitForFunction(() => !['idle', 'scanning', 'preparing'].includes(window.nanopush.session.state.phase), null, { timeout: 30000 });
      }
      stops.push(await timedStop(page));
      await page.waitForFunction(() => window.nanopush.session.state.phase === 'idle', null, { timeout: 30000 });
    }
    out.stop = median(stops.map((r) => r.inPage));
    console.log(`[${label}] Stop during a push: median ${out.stop.toFixed(0)} ms in the page (${stops.map((r) => `${r.inPage.toFixed(0)}/${r.outside}`).join(', ')} ms in the page / from outside)`);
  } finally {
    await browser.close();
    await srv.stop();
  }
  return out;
}

/** A CPU profile's self time (ms) by bundle (the script's file) and by function, the largest first. */
function summarize(p) {
  const dt = new Map();
  // Each sample's time goes to its node: the gaps between samples.
  p.samples.forEach((id, i) => dt.set(id, (dt.get(id) ?? 0) + (p.timeDeltas[i + 1] ?? 0) / 1000));
  const byFile = new Map();
  const byFn = new Map();
  for (const n of p.nodes) {
    const ms = dt.get(n.id) ?? 0;
    if (!ms) continue;
    const f = n.callFrame;
    const file = f.url ? basename(new URL(f.url).pathname).replace(/-[A-Z0-9]{8}\.js$/, '.js') : `(${f.functionName || 'native'})`;
    byFile.set(file, (byFile.get(file) ?? 0) + ms);
    const fn = `${f.functionName || '(anonymous)'} ${file}${f.url ? `:${f.lineNumber + 1}` : ''}`;
    byFn.set(fn, (byFn.get(fn) ?? 0) + ms);
  }
  const top = (m, n) => [...m].sort((a, b) => b[1] - a[1]).slice(0, n);
  return { byFile: top(byFile, 8), byFn: top(byFn, 8) };
}

const line = (x) => `${x.fps.toFixed(1)} frames/s; frame time median ${x.p50.toFixed(0)} ms, p95 ${x.p95.toFixed(0)} ms, worst ${x.max.toFixed(0)} ms`;

function where(x) {
  const m = x.main;
  const pct = (v) => `${((100 * v) / m.wall).toFixed(0)} %`;
  const views = Object.entries(x.per).filter(([, v]) => v.n > 0).sort((a, b) => (b[1].ms || 0) - (a[1].ms || 0))
    .map(([k, v]) => `${k} ${v.n}× ${Number.isFinite(v.ms) ? `${(v.ms / v.n).toFixed(1)} ms` : ''}`.trim());
  return `main thread busy ${pct(m.task)} of the wall time (script ${pct(m.script)}, style ${pct(m.style)}, layout ${pct(m.layout)}, the rest (paint, raster, GPU, idle tasks) ${pct(m.task - m.script - m.style - m.layout)}); ` +
    `views drawn ${views.join(', ')}; JavaScript by bundle ${x.js.byFile.map(([k, v]) => `${k} ${v.toFixed(0)} ms`).join(', ')}; ` +
    `by function ${x.js.byFn.slice(0, 5).map(([k, v]) => `${k} ${v.toFixed(0)} ms`).join(', ')}`;
}

const pages = before ? [['before', before], ['after', WEB]] : [['this page', WEB]];
const results = Object.fromEntries(pages.map(([l]) => [l, []]));
for (let k = 0; k < runs; k++) {
  for (const [label, dir] of pages) results[label].push(await benchOnce(dir, `${label} ${k + 1}`));
}
console.log(`load average at the end ${loadavg().map((l) => l.toFixed(2)).join(' ')}`);
if (runs > 1 || before) {
  const rows = [
    ['page load (KiB, gzip)', (r) => r.load.wireKiB],
    ['map only, idle (frames/s)', (r) => r.idle.fps],
    ['map only, push (frames/s)', (r) => r.push.fps],
    ['map only, push: p95 frame (ms)', (r) => r.push.p95],
    ['map only, push: worst frame (ms)', (r) => r.push.max],
    ['map and 3D, idle (frames/s)', (r) => r.idle3.fps],
    ['map and 3D, push (frames/s)', (r) => r.push3.fps],
    ['map and 3D, push: p95 frame (ms)', (r) => r.push3.p95],
    ['map and 3D, push: worst frame (ms)', (r) => r.push3.max],
    ['Stop, press to reply shown (ms)', (r) => r.stop],
  ];
  console.log(`\nmedians of ${runs} run${runs > 1 ? 's' : ''} each (${pages.map(([l]) => l).join(', ')}${before ? ', after / before' : ''}):`);
  for (const [name, f] of rows) {
    const meds = pages.map(([l]) => median(results[l].map(f)));
    const all = pages.map(([l]) => results[l].map((r) => f(r).toFixed(1)).join(' / '));
    console.log(`| ${name} | ${meds.map((m, i) => `${m.toFixed(1)} (${all[i]})`).join(' | ')}${before ? ` | ${(meds[1] / meds[0]).toFixed(2)}` : ''} |`);
  }
}
