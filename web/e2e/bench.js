// The page's figures for docs/benchmarks.md ("The Nano Visulator in a browser
// (`node e2e/bench.js`)"), measured (not asserted): its transfer size (first load, gzip as
// served) and its frame rate with a 512² scan on screen at 1600×1000 (headless chromium, WebGL on
// SwiftShader), idle and during a push, with the height image as the live map (the default) and
// with the 3D companion view shown too; Stop, from the press to the frame that shows its reply,
// during a push (three presses). (The docs' screenshots: e2e/screenshots.js.)
//   cd web && node e2e/bench.js
import { existsSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { startServer, launchBrowser, newPage, ready, timedStop, serverBin, ROOT } from './support.js';

// The server an operator runs (`make run`: release) when it is built: a debug server's push
// takes a core of its own, which a 2-core machine's browser then lacks. $NANOPUSH_BIN wins.
const release = join(process.env.CARGO_TARGET_DIR ? resolve(ROOT, process.env.CARGO_TARGET_DIR) : join(ROOT, 'target'), 'release', 'nanopush');
if (!process.env.NANOPUSH_BIN && existsSync(release)) process.env.NANOPUSH_BIN = release;
console.log(`server: ${serverBin()}`);
const srv = await startServer();
const browser = await launchBrowser();
try {
  const page = await newPage(browser);
  const cdp = await page.context().newCDPSession(page);
  await cdp.send('Network.enable');
  await cdp.send('Network.setCacheDisabled', { cacheDisabled: true });
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
  console.log(`page load: ${files} requests, ${(wire / 1024).toFixed(0)} KiB on the wire (gzip), ${(raw / 1024).toFixed(0)} KiB uncompressed`);

  const fps = (ms) => page.evaluate((dur) => new Promise((res) => {
    const v = window.nanopush.view;
    const m = window.nanopush.map.frame;
    const f0 = v.frames;
    const m0 = m.frames;
    let n = 0;
    const t0 = performance.now();
    const f = () => {
      n++;
      if (performance.now() - t0 < dur) requestAnimationFrame(f);
      else res({ raf: (n * 1000) / dur, view3d: v.shown ? ((v.frames - f0) * 1000) / dur : 0, renderMs: v.renderMs, map: ((m.frames - m0) * 1000) / dur, mapMs: m.ms });
    };
    requestAnimationFrame(f);
  }), ms);
  await page.click('#take-lease');
  await page.waitForFunction(() => window.nanopush.session.hasLease);
  await page.fill('#scan-size', '16');
  await page.fill('#scan-px', '512');
  await page.click('#scan-btn');
  await page.waitForFunction(() => window.nanopush.session.state.scan?.done, null, { timeout: 60000 });
  await page.waitForTimeout(1000);
  const duringPush = async (dir) => {
    await page.check('input[name=mode][value=by]');
    await page.fill('#distance', '6');
    await page.fill('#direction', dir);
    await page.click('#push-btn');
    await page.waitForFunction(() => !['idle', 'scanning'].includes(window.nanopush.session.state.phase), null, { timeout: 30000 });
    await page.waitForTimeout(1000);
    const r = await fps(4000);
    await page.waitForFunction(() => window.nanopush.session.state.phase === 'idle', null, { timeout: 60000 });
    return r;
  };
  const f = (x) => `${x.raf.toFixed(1)} frames/s (map redrawn ${x.map.toFixed(1)}/s, ${x.mapMs.toFixed(1)} ms each${x.view3d ? `; 3D view ${x.view3d.toFixed(1)}/s, ${x.renderMs.toFixed(1)} ms each` : ''})`;
  // The default: the height image as the live map, the 3D view hidden.
  const idle = await fps(3000);
  const pushing = await duringPush('180');
  console.log(`512² scan at 1600×1000, map only, idle: ${f(idle)}`);
  console.log(`512² scan at 1600×1000, map only, during a push: ${f(pushing)}`);
  // With the 3D companion shown beside it.
  await page.click('#toggle-3d');
  await page.waitForTimeout(1000);
  const idle3 = await fps(3000);
  const pushing3 = await duringPush('0');
  console.log(`512² scan at 1600×1000, map and 3D view, idle: ${f(idle3)}`);
  console.log(`512² scan at 1600×1000, map and 3D view, during a push: ${f(pushing3)}`);
  await page.click('#toggle-3d');
  const stops = [];
  for (let k = 0; k < 3; k++) {
    const running = await page.evaluate(() => !['idle', 'scanning'].includes(window.nanopush.session.state.phase));
    if (!running) {
      await page.fill('#direction', k % 2 ? '0' : '180');
      await page.click('#push-btn');
      await page.waitForFunction(() => !['idle', 'scanning'].includes(window.nanopush.session.state.phase), null, { timeout: 30000 });
    }
    stops.push(await timedStop(page));
    await page.waitForFunction(() => window.nanopush.session.state.phase === 'idle', null, { timeout: 30000 });
  }
  const inPage = stops.map((r) => r.inPage).sort((x, y) => x - y);
  console.log(`Stop during a push, 512² scan at 1600×1000: median ${inPage[1].toFixed(0)} ms in the page (${stops.map((r) => `${r.inPage.toFixed(0)}/${r.outside}`).join(', ')} ms in the page / from outside)`);
} finally {
  await browser.close();
  await srv.stop();
}
