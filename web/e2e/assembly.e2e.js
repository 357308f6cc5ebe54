// Assembling a pattern from the page, in a real browser against the real `nanopush serve` (the
// quick gold-latex scene of support.js): the Assemble panel's editor (sites placed on the map by
// click and by keys, a preset dropped and dragged, refusals in words), Plan (the assignment and
// the path drawn, nothing moves), Assemble (move 1 of 1, the site turns solid, the report), a
// viewer joining mid-assembly and Stop. The tests run in order on one server and one operator
// page. Screenshots go to web/test-results/.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startServer, launchBrowser, newPage, getJson, shot, axe, ready, waitText, WEB } from './support.js';

let srv;
let browser;
let op;

before(async () => {
  // The full frame an assembly starts from (the scene's scan) holds the three particles, each
  // four pixels across.
  srv = await startServer({ webDir: process.env.E2E_WEB_DIR || WEB, scan: { centre_x_um: 55, centre_y_um: 46, size_um: 40, pixels: 160 } });
  browser = await launchBrowser();
});

after(async () => {
  await browser?.close();
  await srv?.stop();
});

/** The client point (px) of a stage point (µm) on the page's map. */
const clientAt = (page, xUm, yUm) => page.evaluate(([x, y]) => {
  const g = window.nanopush.image2d.geometry();
  const e = window.nanopush.image2d.extent();
  const r = window.nanopush.image2d.container.getBoundingClientRect();
  return [r.left + g.x + ((x * 1e-6 - e.x_offset) / e.x_real) * g.w, r.top + g.y + g.h - ((y * 1e-6 - e.y_offset) / e.y_real) * g.h];
}, [xUm, yUm]);

/** The pattern's sites (µm), as the panel holds them. */
const sites = (page) => page.evaluate(() => window.nanopush.app.assemble.panel.pattern.sites.map((s) => [Number(s.x_um.toFixed(2)), Number(s.y_um.toFixed(2))]));

/** Waits until the map has drawn `n` elements matching `sel` (at least). */
const drawn = (page, sel, n = 1, timeout = 10000) => page.waitForFunction(([s, k]) => document.querySelectorAll(s).length >= k, [sel, n], { timeout });

/** Axe's serious and critical violations on the page. */
const serious = async (page) => (await axe(page)).filter((v) => v.impact === 'serious' || v.impact === 'critical');

test('the pattern is drawn on the map: click, preset, drag, keys, refusals in words', async () => {
  op = await newPage(browser);
  await op.goto(srv.url);
  await ready(op);
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  // The panel's code comes when it is first opened.
  const chunks = async () => (await op.evaluate(() => performance.getEntriesByType('resource').map((r) => new URL(r.name).pathname))).filter((u) => /assemblepanel-/.test(u));
  assert.deepEqual(await chunks(), [], 'not loaded while the panel is closed');
  await op.click('#asm-open');
  await op.waitForFunction(() => window.nanopush.app.assemble.panel !== null);
  assert.equal((await chunks()).length, 1);
  assert.match(await op.textContent('#asm-why'), /Place at least one site/);
  assert.equal(await op.isDisabled('#asm-plan'), true);
  // A click with "Place sites" off picks a push target, not a site.
  await op.mouse.click(...await clientAt(op, 30, 70));
  assert.deepEqual(await sites(op), []);
  assert.equal(await op.inputValue('#to-x'), '30.00');
  await op.click('#asm-place');
  assert.equal(await op.getAttribute('#asm-place', 'aria-pressed'), 'true');
  await op.mouse.click(...await clientAt(op, 30, 70));
  await drawn(op, '.map-svg .asm-site');
  assert.deepEqual(await sites(op), [[30, 70]]);
  // A ring of 4 dropped at (60, 60), then dragged by one of its sites 5 µm left: all four move.
  await op.selectOption('#asm-kind', 'ring');
  await op.fill('#asm-n', '4');
  await op.fill('#asm-radius', '3');
  await op.fill('#asm-x', '60');
  await op.fill('#asm-y', '60');
  await op.click('#asm-drop');
  await drawn(op, '.map-svg .asm-site', 5);
  const grab = await clientAt(op, 63, 60);
  const to = await clientAt(op, 58, 60);
  await op.mouse.move(...grab);
  await op.mouse.down();
  await op.mouse.move((grab[0] + to[0]) / 2, grab[1], { steps: 3 });
  await op.mouse.move(...to, { steps: 3 });
  await op.mouse.up();
  const moved = await sites(op);
  assert.ok(Math.abs(moved[1][0] - 58) < 0.3 && Math.abs(moved[3][0] - 52) < 0.3, `the ring moved whole: ${JSON.stringify(moved)}`);
  assert.equal(await op.textContent('#asm-count'), '5 sites');
  // By keys on the map (its cursor starts on the selected particle, #1 at (40, 30)): Enter adds
  // a site there, `m` brings the selected site to the cursor, Delete removes it; each is said.
  await op.focus('.map-svg');
  await op.keyboard.press('Enter');
  await waitText(op, '#announce', /^site 6 added at \(40\.00, 30\.00\) µm$/, 5000);
  await op.keyboard.press('Shift+ArrowUp');
  await op.keyboard.press('m');
  await waitText(op, '#announce', /^site 6 moved: site 6 now at \(40\.00, 40\.00\) µm$/, 5000);
  assert.deepEqual((await sites(op))[5], [40, 40]);
  await op.keyboard.press('Delete');
  await waitText(op, '#announce', /^site 6 removed; 5 left$/, 5000);
  // The list's Remove button, by keyboard too.
  await op.focus('#asm-sites tr:nth-child(1) button');
  await op.keyboard.press('Enter');
  await waitText(op, '#announce', /^site 1 removed; 4 left$/, 5000);
  assert.equal((await sites(op)).length, 4);
  // Out of range: the preset's field named with its allowed range; nothing added.
  await op.fill('#asm-n', '1');
  await op.selectOption('#asm-kind', 'line');
  await op.click('#asm-drop');
  assert.equal(await op.textContent('#asm-error'), 'line sites: 1 is out of range; allowed: a whole number in [2, 400]');
  assert.equal((await sites(op)).length, 4);
  await op.click('#asm-clear');
  assert.deepEqual(await sites(op), []);
  assert.deepEqual(await serious(op), []);
  assert.deepEqual(op.errors, []);
  await shot(op, 'asm-01-editor');
});

test('Plan draws the assignment and the path; nothing moves', async () => {
  const before = (await getJson(srv.base, '/api/status')).particles.find((p) => p.id === 1);
  // One site 2 µm right of particle 1 (40, 30).
  await op.mouse.click(...await clientAt(op, before.x * 1e6 + 2, before.y * 1e6));
  await op.click('#asm-place'); // off again: the map picks particles
  assert.equal(await op.isDisabled('#asm-plan'), false);
  await op.click('#asm-plan');
  await waitText(op, '#asm-progress', /1 move planned for 1 site: 1 site to fill\. Nothing moved/, 120000);
  await drawn(op, '.map-svg .asm-path.fill');
  await drawn(op, '.map-svg .asm-assign');
  const after = (await getJson(srv.base, '/api/status')).particles.find((p) => p.id === 1);
  assert.equal(after.x, before.x, 'plan only: particle 1 stayed');
  assert.match(await op.textContent('#log'), /assembly \d+ \(yours\) planned, to look at/);
  assert.deepEqual(op.errors, []);
  await shot(op, 'asm-02-planned');
});

test('Assemble moves it: move 1 of 1, the site turns solid, the report in words', async () => {
  await op.click('#asm-run');
  await waitText(op, '#asm-progress', /^Move 1 of 1: #1 fills site 1/, 120000);
  await drawn(op, '.map-svg .asm-path.current');
  await op.waitForFunction(() => window.nanopush.session.state.assembly?.done?.summary, null, { timeout: 180000 });
  await drawn(op, '.map-svg .asm-site.filled');
  // The map shows the last full frame the sites were judged by (the assembly's record names it).
  await waitText(op, '#img-title', /scan-/, 20000);
  const outcome = await op.textContent('#asm-outcome');
  assert.match(outcome, /^Assembled: every site holds a particle within its tolerance · record assembly-/, outcome);
  const row = await op.$$eval('#asm-rows tr', (rs) => rs.map((r) => [...r.cells].map((c) => c.textContent)));
  assert.equal(row.length, 1);
  assert.equal(row[0][2], 'filled');
  assert.match(row[0][4], /^\d+\.\d nm/, 'its error in nm');
  assert.match(await op.textContent('#asm-times'), /^Took .* for .* of the instrument's time/);
  // The report lengthens the side column, which scrolls: the page does not.
  assert.ok(await op.evaluate(() => document.documentElement.scrollHeight <= window.innerHeight), 'the page scrolls');
  // No protocol words in what people read.
  const words = await op.textContent('#asm-panel');
  assert.doesNotMatch(words, /plan_only|assembly_|incomplete|unreachable|\bfill\b/);
  assert.deepEqual(await serious(op), []);
  assert.deepEqual(op.errors, []);
  await shot(op, 'asm-03-assembled');
});

test('a viewer joining mid-assembly sees it; Stop ends it and the report says so', async () => {
  // Two sites, beside particles 2 (55, 62) and 3 (70, 45).
  await op.click('#asm-clear');
  await op.click('#asm-place');
  await op.mouse.click(...await clientAt(op, 57, 62));
  await op.mouse.click(...await clientAt(op, 72, 45));
  await op.click('#asm-place');
  await op.click('#asm-run');
  await waitText(op, '#asm-progress', /^Move 1 of /, 180000);
  const v = await newPage(browser);
  await v.goto(`${srv.base}/`);
  await ready(v);
  await v.waitForFunction(() => window.nanopush.session.state.assembly?.moving, null, { timeout: 20000 });
  // Anyone's assembly opens the panel, to show it.
  await v.waitForFunction(() => !document.querySelector('#asm-body').hidden, null, { timeout: 10000 });
  await drawn(v, '.map-svg .asm-site', 2);
  assert.match(await v.textContent('#asm-progress'), /^Move \d+ of \d+/);
  assert.equal(await v.isVisible('#asm-fs'), false, 'no editor for a viewer');
  await op.click('#stop-btn');
  await waitText(op, '#asm-outcome', /^Stopped/, 60000);
  await waitText(v, '#asm-outcome', /^Stopped/, 20000);
  assert.deepEqual(v.errors, []);
  assert.deepEqual(op.errors, []);
  await shot(v, 'asm-04-viewer-stopped');
  await v.context().close();
});
