// The Nano Visulator on a real controller, in a real browser: `nanopush serve --instrument`
// against the fake Nanonis controller (`nanopush-fake-nanonis`, started here on free ports). The
// page names the backend and the rate its readings come at, follows the controller's tip, shows a
// scan of the controller's own frame, and disables what the server does not run there, saying why. Run by `npm run e2e`.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { createInterface } from 'node:readline';
import { dirname, join } from 'node:path';
import { startServer, launchBrowser, newPage, ready, waitText, serverBin, shot, ROOT } from './support.js';

let fake;
let srv;
let browser;

/** Starts the fake controller on free ports: the child and its two ports. */
async function startFake() {
  const bin = join(dirname(serverBin()), 'nanopush-fake-nanonis');
  const child = spawn(bin, ['--port', '0', '--logger-port', '0'], { cwd: ROOT, stdio: ['ignore', 'pipe', 'pipe'] });
  const line = await new Promise((res, rej) => {
    const t = setTimeout(() => rej(new Error('the fake controller did not start within 10 s')), 10000);
    child.on('exit', (code) => rej(new Error(`the fake controller exited (${code})`)));
    createInterface({ input: child.stdout }).once('line', (l) => { clearTimeout(t); res(l); });
  });
  const m = /command port (\d+), logger port (\d+)/.exec(line);
  if (!m) throw new Error(`unexpected first line ${JSON.stringify(line)}`);
  return { child, port: Number(m[1]), logger: Number(m[2]) };
}

before(async () => {
  fake = await startFake();
  srv = await startServer({ extra: ['--instrument', `nanonis:127.0.0.1:${fake.port},${fake.logger}`] });
  browser = await launchBrowser();
});

after(async () => {
  await browser?.close();
  await srv?.stop();
  fake?.child.kill('SIGTERM');
});

test('the page names the controller and its rate, follows its tip, scans its frame, disables the rest', async () => {
  const page = await newPage(browser, { width: 1280, height: 800 });
  await page.goto(srv.url);
  await ready(page);
  const status = await waitText(page, '#instrument-status', /^Nanonis 127\.0\.0\.1:\d+ · signals at .*Hz · force held by the controller$/, 15000);
  assert.match(status, new RegExp(`127\\.0\\.0\\.1:${fake.port}`));
  // The fake's tip sits at the centre of its frame, (50, 50) µm: telemetry follows it.
  await page.waitForFunction(() => {
    const t = window.nanopush.session.state.tip;
    return t && Math.abs(t.stage[0] - 50e-6) < 1e-9 && Math.abs(t.stage[1] - 50e-6) < 1e-9;
  }, null, { timeout: 15000 });
  assert.deepEqual(await page.evaluate(() => window.nanopush.session.state.particles), [], 'the scene\'s particles are not the sample');
  await page.click('#take-lease');
  await page.waitForFunction(() => window.nanopush.session.hasLease);
  assert.equal(await page.isDisabled('#push-btn'), true, 'Push is disabled on a real controller');
  const why = await page.getAttribute('#push-btn', 'title') ?? '';
  const note = await page.textContent('body');
  assert.match(why + note, /nanopush push --instrument/);
  assert.equal(await page.getAttribute('#stop-btn', 'aria-disabled'), 'false', 'Stop stays: it withdraws the tip');
  // Scans run through the controller's scan engine, on its own frame: the square's fields are off.
  assert.equal(await page.isDisabled('#scan-btn'), false, 'Scan is offered');
  assert.equal(await page.isDisabled('#scan-size'), true, 'the controller\'s own frame');
  await page.click('#scan-btn');
  await page.waitForFunction(() => window.nanopush.session.state.scan?.done, null, { timeout: 30000 });
  const scan = await page.evaluate(() => window.nanopush.session.state.scan);
  assert.equal(scan.xres, 64, 'the fake\'s buffer: 64 × 64');
  assert.ok(Math.abs(scan.x_offset - 25e-6) < 1e-9 && Math.abs(scan.x_real - 50e-6) < 1e-9, JSON.stringify(scan));
  await page.waitForFunction(() => /64 of 64 lines/.test(document.querySelector('#image2d svg')?.getAttribute('aria-label') ?? ''), null, { timeout: 10000 });
  assert.deepEqual(page.errors, []);
  await shot(page, 'nanonis');
});
