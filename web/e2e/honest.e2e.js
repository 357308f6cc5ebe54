// The Nano Visulator stays honest when the server goes away, in a real browser
// against the real `nanopush serve`: a server killed with SIGKILL mid-push and started again on
// the same port and records (the page says "unknown" while it is down, then that the server
// restarted and that the push's outcome is unknown; the monitor says "server down since" and
// keeps the run history from disk), a server killed mid-scan (its scan "interrupted", one
// "connection closed" however many attempts fail), a viewer away while a scan ends (it gets the
// whole scan when back), a hung server (SIGSTOP: shown as down, then back), and a lease holder who
// reloads mid-push (warned first; the push ends "stopped: the lease holder disconnected", in a
// neutral colour). Run by `npm run e2e`.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startServer, launchBrowser, newPage, getJson, shot, ready, waitText, pushBy, clippedIn, WEB } from './support.js';

let srv;
let browser;

before(async () => {
  srv = await startServer({ webDir: process.env.E2E_WEB_DIR || WEB });
  browser = await launchBrowser();
});

after(async () => {
  await browser?.close();
  await srv?.stop();
});

const running = (page) => page.waitForFunction(() => window.nanopush.session.state.push && !['idle', 'scanning'].includes(window.nanopush.session.state.phase), null, { timeout: 30000 });

test('kill -9 mid-push and a restart: "unknown", then the lost push told', async () => {
  const op = await newPage(browser, { width: 1280, height: 720 });
  await op.goto(srv.url);
  await ready(op);
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await pushBy(op, 1, 0);
  await waitText(op, '#lastrun', /^push of #1 ok/, 60000);
  // The wall screen, on a phone.
  const mon = await newPage(browser, { width: 390, height: 844 });
  await mon.goto(srv.base + '/?view=monitor');
  await waitText(mon, '#m-runs', /push of #1 ok/, 15000);
  await waitText(mon, '#m-conn', /^live/, 10000);
  await pushBy(op, 20, 180);
  await running(op);
  assert.equal(await op.isVisible('#push-now'), true);
  assert.equal(await op.textContent('#reply-push'), 'push accepted: running');
  await srv.kill('SIGKILL');
  // While it is down: nothing the server said is shown as if it still held.
  await op.waitForFunction(() => document.body.classList.contains('offline'), null, { timeout: 10000 });
  assert.equal(await op.textContent('#st-phase'), 'unknown');
  assert.equal(await op.textContent('#st-lease'), 'unknown');
  // The push is not "running", nor gone: its outcome is unknown until the server is back.
  assert.match(await op.textContent('#push-now-text'), /^Push of #1 \(you\): outcome unknown until the server is back/);
  assert.doesNotMatch(await op.textContent('#push-now'), /Pushing/);
  assert.equal(await op.textContent('#reply-push'), 'push outcome unknown: disconnected', 'not "accepted"');
  assert.equal(await op.isVisible('#offline'), true);
  // The page cannot tell a dead server from a lost network: it says what a running one does.
  const log = await op.textContent('#log');
  assert.match(log, /the connection closed while the push of #1 ran: its outcome is unknown until the server is back/);
  assert.doesNotMatch(log, /\(the server stops a push/, 'no claim about what a dead server does');
  // Stop (Esc) cannot reach the server, and says so and what the server does on its own.
  await op.keyboard.press('Escape');
  const refused = await waitText(op, '#reply-stop', /^Stop cannot reach the server/, 5000);
  assert.match(refused, /A running server stops a push whose lease holder is gone on its own/);
  await waitText(op, '#announce', /^Stop cannot reach the server/, 5000);
  assert.deepEqual(await clippedIn(op, ['.ctl', '.map-head', '.readouts']), [], 'the outage\'s texts whole');
  // Narrower, the title's tags wrap rather than end in an ellipsis.
  await op.setViewportSize({ width: 1000, height: 720 });
  assert.deepEqual(await clippedIn(op, ['.ctl', '.map-head', '.readouts']), [], 'the outage\'s texts whole at 1000 px');
  await op.setViewportSize({ width: 1280, height: 720 });
  assert.equal(await op.textContent('#reply-lease'), 'lease lost with the connection', 'not "lease taken"');
  // The monitor says since when the server is down, in its banner, and keeps the history.
  await waitText(mon, '#m-conn', /^server down since \d\d:\d\d:\d\d \(it cannot be reached\)/, 10000);
  const banner = await mon.$eval('#m-conn', (e) => ({ cls: e.className, size: parseFloat(getComputedStyle(e).fontSize) }));
  assert.equal(banner.cls, 'm-conn down');
  assert.ok(banner.size >= 20, `the banner's type is ${banner.size} px`);
  assert.equal(await mon.evaluate(() => document.body.classList.contains('offline')), true, 'the tiles are greyed');
  await shot(op, '20-server-killed');
  await shot(mon, '21-monitor-server-down');
  // Started again, same port, same records.
  const port = Number(srv.addr.split(':').pop());
  srv = await startServer({ webDir: process.env.E2E_WEB_DIR || WEB, port, dir: srv.dir });
  await waitText(op, '#log', /the server restarted/, 15000);
  const lost = await waitText(op, '#lastrun', /outcome unknown/, 10000);
  assert.match(lost, /push of #1: outcome unknown: the server restarted while it ran/);
  assert.equal(await op.getAttribute('#lastrun', 'class'), 'lastrun unknown');
  assert.equal(await op.isVisible('#push-now'), false);
  assert.equal(await op.textContent('#reply-push'), 'push outcome unknown', 'after the restart: not "accepted"');
  assert.equal(await op.evaluate(() => document.body.classList.contains('offline')), false);
  assert.notEqual(await op.textContent('#st-phase'), 'unknown');
  // The monitor after the restart: live, and the history from disk still there.
  await waitText(mon, '#m-conn', /^live · the server restarted at \d\d:\d\d:\d\d/, 15000);
  await waitText(mon, '#m-runs', /push of #1 ok/, 10000);
  const w = await mon.evaluate(() => ({ scroll: document.documentElement.scrollWidth, inner: window.innerWidth }));
  assert.ok(w.scroll <= w.inner, `the monitor is ${w.scroll} px wide at ${w.inner} px`);
  await shot(mon, '22-monitor-after-restart');
  assert.deepEqual(op.errors.filter((e) => !/ERR_CONNECTION_REFUSED|Failed to load resource/.test(e)), []);
  assert.deepEqual(mon.errors.filter((e) => !/ERR_CONNECTION_REFUSED|Failed to load resource/.test(e)), []);
  await mon.context().close();
  await op.context().close();
});

test('kill -9 mid-scan: the scan is interrupted, one "connection closed"', async () => {
  const op = await newPage(browser, { width: 1280, height: 720 });
  await op.goto(srv.url);
  await ready(op);
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await op.evaluate(() => window.nanopush.app.conn.send({ type: 'scan', size_um: 16, pixels: 512 }));
  await op.waitForFunction(() => (window.nanopush.session.state.scan?.lines ?? 0) > 5, null, { timeout: 20000 });
  await srv.kill('SIGKILL');
  // Down long enough for a few refused attempts (0.25 s, 0.5 s, 1 s …).
  await op.waitForFunction(() => window.nanopush.app.conn.attempt >= 4, null, { timeout: 15000 });
  const closed = await op.$$eval('#log li', (ls) => ls.filter((l) => /connection closed \(code/.test(l.textContent)).length);
  assert.equal(closed, 1, 'one "connection closed", not one per attempt');
  const port = Number(srv.addr.split(':').pop());
  srv = await startServer({ webDir: process.env.E2E_WEB_DIR || WEB, port, dir: srv.dir });
  await waitText(op, '#log', /the server restarted/, 15000);
  // The killed scan: interrupted, and from before the restart.
  const progress = await waitText(op, '#scan-progress', /interrupted/, 5000);
  assert.match(progress, /^scan 1 interrupted at line \d+\/512 · from before the server restarted$/);
  assert.equal(await op.isVisible('#img-stale'), true);
  assert.match(await op.textContent('#img-stale'), /from before the server restarted/);
  assert.deepEqual(op.errors.filter((e) => !/ERR_CONNECTION_REFUSED|Failed to load resource/.test(e)), []);
  await op.context().close();
});

test('a viewer away while a scan ends gets it whole when back', async () => {
  const op = await newPage(browser);
  await op.goto(srv.url);
  await ready(op);
  const viewer = await newPage(browser);
  await viewer.goto(srv.base + '/');
  await ready(viewer);
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await op.evaluate(() => window.nanopush.app.conn.send({ type: 'scan', size_um: 16, pixels: 512 }));
  await viewer.waitForFunction(() => (window.nanopush.session.state.scan?.lines ?? 0) > 5);
  // The viewer's network goes: its reconnects fail until the scan has ended.
  const url = await viewer.evaluate(() => {
    const c = window.nanopush.app.conn;
    const u = c.url;
    c.url = 'ws://127.0.0.1:1/ws';
    c.ws.close();
    return u;
  });
  await op.waitForFunction(() => window.nanopush.session.state.scan?.done, null, { timeout: 30000 });
  const away = await viewer.evaluate(() => window.nanopush.session.state.scan.lines);
  assert.ok(away < 512, `the viewer saw ${away} lines`);
  await viewer.evaluate((u) => {
    window.nanopush.app.conn.url = u;
    window.nanopush.app.conn.connect();
  }, url);
  await ready(viewer);
  // All 512 lines, not the ones it saw before it went.
  await viewer.waitForFunction(() => {
    const sc = window.nanopush.session.state.scan;
    return sc.done && sc.lines === 512;
  }, null, { timeout: 15000 });
  assert.match(await viewer.textContent('#scan-progress'), /^scan \d+ complete/);
  assert.deepEqual(viewer.errors.filter((e) => !/ERR_CONNECTION_REFUSED|127\.0\.0\.1:1\/|Failed to load resource/.test(e)), []);
  await viewer.context().close();
  await op.context().close();
});

test('a hung server (SIGSTOP) is shown as down, and as back when it resumes', async () => {
  const mon = await newPage(browser, { width: 800, height: 600 });
  await mon.goto(srv.base + '/?view=monitor');
  await waitText(mon, '#m-conn', /^live/, 15000);
  const op = await newPage(browser, { width: 1280, height: 720 });
  await op.goto(srv.url);
  await ready(op);
  // No close, no answer: the monitor says so within 3 s, the page gives up within 5 s.
  process.kill(srv.pid, 'SIGSTOP');
  try {
    await waitText(mon, '#m-conn', /^server down since \d\d:\d\d:\d\d \(no answer within 3 s\)/, 10000);
    await op.waitForFunction(() => document.body.classList.contains('offline'), null, { timeout: 10000 });
    await waitText(op, '#log', /connection closed \(no word from the server for 5 s\)/, 1000);
  } finally {
    process.kill(srv.pid, 'SIGCONT');
  }
  await ready(op);
  await waitText(mon, '#m-conn', /^live · the server was unreachable from/, 10000);
  assert.equal(await op.evaluate(() => document.body.classList.contains('offline')), false);
  assert.deepEqual(op.errors, []);
  assert.deepEqual(mon.errors, []);
  await mon.context().close();
  await op.context().close();
});

test('a holder reloading mid-push is warned; the push ends "stopped", neutral', async () => {
  const op = await newPage(browser);
  await op.goto(srv.url);
  await ready(op);
  const viewer = await newPage(browser);
  await viewer.goto(srv.base + '/');
  await ready(viewer);
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await pushBy(op, 20, 0);
  await running(op);
  const dialogs = [];
  op.on('dialog', (d) => {
    dialogs.push(d.type());
    d.accept();
  });
  await op.reload();
  assert.deepEqual(dialogs, ['beforeunload'], 'warned before leaving mid-push');
  const text = await waitText(viewer, '#lastrun', /^push of #1 stopped/, 30000);
  assert.match(text, /^push of #1 stopped: the lease holder disconnected/);
  assert.equal(await viewer.getAttribute('#lastrun', 'class'), 'lastrun neutral');
  const [newest] = await getJson(srv.base, '/api/runs');
  assert.equal(newest.outcome, 'stopped');
  assert.equal(newest.failure, 'stopped: the lease holder disconnected');
  // The reloaded page reads how its push ended.
  await ready(op);
  await waitText(op, '#lastrun', /stopped: the lease holder disconnected/, 10000);
  await shot(op, '23-reloaded-mid-push');
  assert.deepEqual(op.errors, []);
  assert.deepEqual(viewer.errors, []);
  await viewer.context().close();
  await op.context().close();
});
