// The docs' screenshots of the Nano Visulator (docs/server.md), taken in headless chromium
// against the real `nanopush serve` (the quick gold-latex scene of the browser tests): the
// operator's view at 1280×720 during a push over a 128² scan (the map with the particles, the
// tip, the planned path and the live trail; a line profile), the wall-screen monitor at
// 1280×800, and a 390×844 phone.
//   cd web && node e2e/screenshots.js ../docs
import { join } from 'node:path';
import { startServer, launchBrowser, newPage, ready } from './support.js';

const out = process.argv[2] ?? '../docs';
const srv = await startServer();
const browser = await launchBrowser();
try {
  const op = await newPage(browser, { width: 1280, height: 720 });
  await op.goto(srv.url);
  await ready(op);
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await op.fill('#scan-size', '12');
  await op.fill('#scan-px', '128');
  await op.click('#scan-btn');
  await op.waitForFunction(() => window.nanopush.session.state.scan?.done, null, { timeout: 60000 });
  // A line profile across the particle, then a push of 3 µm to the right, caught half-way.
  const g = await op.evaluate(() => window.nanopush.image2d.geometry());
  const box = await op.$eval('#image2d', (e) => { const r = e.getBoundingClientRect(); return { x: r.left, y: r.top }; });
  const at = (fx, fy) => [box.x + g.x + fx * g.w, box.y + g.y + g.h - fy * g.h];
  await op.mouse.move(...at(0.25, 0.62));
  await op.mouse.down();
  await op.mouse.move(...at(0.75, 0.38), { steps: 5 });
  await op.mouse.up();
  await op.check('input[name=mode][value=by]');
  await op.fill('#distance', '3');
  await op.fill('#direction', '0');
  await op.click('#push-btn');
  await op.waitForFunction(() => window.nanopush.map.trail.pts.length > 15 && window.nanopush.session.state.push, null, { timeout: 90000, polling: 50 });
  await op.mouse.move(...at(0.6, 0.5));
  await op.waitForTimeout(400);
  await op.screenshot({ path: join(out, 'visulator.png') });
  await op.waitForFunction(() => window.nanopush.session.state.phase === 'idle', null, { timeout: 60000 });

  const mon = await newPage(browser, { width: 1280, height: 800 });
  await mon.goto(srv.base + '/?view=monitor');
  await mon.waitForFunction(() => /push of #1/.test(document.querySelector('#m-runs')?.textContent ?? '') && /scan 1/.test(document.querySelector('#m-thumb-cap')?.textContent ?? ''), null, { timeout: 20000 });
  await mon.waitForTimeout(600);
  await mon.screenshot({ path: join(out, 'monitor.png') });

  const phone = await newPage(browser, { width: 390, height: 844 });
  await phone.goto(srv.url);
  await ready(phone);
  await phone.waitForFunction(() => window.nanopush.session.state.scan?.done && window.nanopush.image2d.frame.frames > 0, null, { timeout: 20000 });
  await phone.waitForTimeout(600);
  await phone.screenshot({ path: join(out, 'visulator-phone.png') });
  console.log(`screenshots in ${out}: visulator.png, monitor.png, visulator-phone.png`);
} finally {
  await browser.close();
  await srv.stop();
}
