// The Nano Visulator in a real browser (Debian's chromium, headless, WebGL2 on SwiftShader)
// against the real `nanopush serve`. Run by `make web-test` (`npm run e2e`); the
// server binary must be built (target/debug, or $CARGO_TARGET_DIR, or $NANOPUSH_BIN).
// Screenshots go to web/test-results/. The tests run in order and share one server: the
// operator's scan and push are what the late viewer must see.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, symlinkSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { startServer, launchBrowser, newPage, getJson, shot, axe, ready, timedStop, waitText, pushBy, clippedIn, requested, WEB, TOKEN } from './support.js';

let srv;
let browser;
let op; // the operator's page, kept across tests

before(async () => {
  srv = await startServer({ webDir: process.env.E2E_WEB_DIR || WEB });
  browser = await launchBrowser();
});

after(async () => {
  await browser?.close();
  await srv?.stop();
});

const state = (page) => page.evaluate(() => {
  const s = window.nanopush.session.state;
  return { particles: s.particles, lease: s.lease, client: s.client, scan: s.scan && { id: s.scan.id, lines: s.scan.lines, yres: s.scan.yres, x_offset: s.scan.x_offset, y_offset: s.scan.y_offset, x_real: s.scan.x_real, y_real: s.scan.y_real, done: s.scan.done, record: s.scan.record }, stale: s.scanStale, push: s.push };
});

test('the operator page loads with no console errors or axe violations', async () => {
  op = await newPage(browser);
  await op.goto(srv.url);
  await ready(op);
  // Drawn at least twice (the first frames are where a renderer error would show).
  await op.waitForFunction(() => window.nanopush.map.frame.frames >= 2 && window.nanopush.image2d.frame.frames >= 1, null, { timeout: 20000 });
  assert.deepEqual(op.errors, []);
  const v = await axe(op);
  assert.deepEqual(v, [], JSON.stringify(v, null, 1));
  await shot(op, '01-operator-loaded');
});

test('three.js waits for the 3D view; the scene and session come once', async () => {
  await op.waitForLoadState('networkidle');
  const urls = await requested(op);
  assert.deepEqual(urls.filter((u) => /view3d-/.test(u)), [], 'the 3D view\'s chunk is not loaded while the view is hidden');
  const js = urls.filter((u) => u.startsWith('/dist/') && u.endsWith('.js'));
  assert.ok(js.length >= 2, `the page's scripts: ${js}`);
  assert.equal(urls.filter((u) => u === '/api/scene').length, 1, `/api/scene: ${urls}`);
  assert.equal(urls.filter((u) => u === '/api/session').length, 1, `/api/session: ${urls}`);
  assert.equal(await op.evaluate(() => window.nanopush.app.view.loaded), false);
});

test('before any scan the particle\'s ring shows around the tip', async () => {
  await op.waitForFunction(() => !document.querySelector('.map-dot.tip').hidden, null, { timeout: 10000 });
  const m = await op.evaluate(() => {
    const c = document.querySelector('.map-svg .belief circle[data-id="1"]');
    const t = document.querySelector('.map-dot.tip').getBoundingClientRect();
    const l = [...document.querySelectorAll('.map-svg .map-label')].find((e) => e.textContent === '#1');
    const lr = l.getBoundingClientRect();
    return { r: Number(c.getAttribute('r')), tipHalf: t.width / 2, label: lr.width > 0 && lr.height > 0 };
  });
  assert.equal(await op.evaluate(() => window.nanopush.session.state.scan), null, 'no scan yet: the whole stage');
  // The 250 nm particle is 1.5 px at this scale: its ring is drawn 10 px, wider than the tip.
  assert.ok(m.r >= 10 && m.r > m.tipHalf + 2, `ring ${m.r} px, tip ${m.tipHalf} px`);
  assert.ok(m.label, 'the particle\'s id beside its ring');
});

test('the tip is on screen, drawn over everything, covered by nothing', async () => {
  // On the height image (the map) first: the tip's mark sits inside the image.
  await op.waitForFunction(() => !document.querySelector('.map-dot.tip').hidden, null, { timeout: 10000 });
  const onMap = await op.evaluate(() => {
    const t = document.querySelector('.map-dot.tip').getBoundingClientRect();
    const i = document.querySelector('#image2d').getBoundingClientRect();
    return t.left >= i.left && t.right <= i.right && t.top >= i.top && t.bottom <= i.bottom && t.width > 4;
  });
  assert.ok(onMap, 'the tip is marked on the height image');
  // The 3D view is the optional companion: shown on request, three.js loaded then.
  assert.equal(await op.isVisible('#view3d'), false, 'the 3D view is hidden until asked for');
  await op.click('#toggle-3d');
  await op.waitForFunction(() => window.nanopush.app.view.loaded && window.nanopush.view.frames >= 2 && window.nanopush.view.tip.ball.visible, null, { timeout: 20000 });
  assert.equal((await requested(op)).filter((u) => /view3d-/.test(u)).length, 1, 'its chunk loaded once asked for');
  await op.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const t = await op.evaluate(() => {
    const v = window.nanopush.view;
    const p = v.tip.ball.position.clone().project(v.camera);
    const r = v.container.getBoundingClientRect();
    const x = r.left + ((p.x + 1) / 2) * r.width;
    const y = r.top + ((1 - p.y) / 2) * r.height;
    const hit = document.elementFromPoint(x, y);
    return {
      onScreen: Math.abs(p.x) < 1 && Math.abs(p.y) < 1,
      covered: hit ? (hit.closest('.plabel, .overlay > *') ? hit.className || hit.tagName : null) : 'nothing',
      depthTest: v.tip.ball.material.depthTest,
    };
  });
  assert.ok(t.onScreen, 'the tip is in the view');
  assert.equal(t.covered, null, `the tip is covered by ${t.covered}`);
  assert.equal(t.depthTest, false, 'drawn through the scan and the particles');
  await op.click('#toggle-3d');
  assert.equal(await op.isVisible('#view3d'), false);
});

test('the operator scans and pushes; /api/status shows the particle moved', async () => {
  await op.click('#take-lease');
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await op.fill('#scan-size', '10');
  await op.fill('#scan-px', '32');
  await op.click('#scan-btn');
  await op.waitForFunction(() => /32 of 32 lines/.test(document.querySelector('#image2d svg')?.getAttribute('aria-label') ?? ''), null, { timeout: 30000 });
  assert.equal(await op.textContent('#reply-lease'), 'lease taken', 'replies in words');
  assert.equal(await op.textContent('#reply-scan'), 'scan started');
  const before = await getJson(srv.base, '/api/status');
  const p0 = before.particles.find((p) => p.id === 1);
  // The map previews the push before it is sent: from the particle, 1 µm towards +x (0°).
  await op.check('input[name=mode][value=by]');
  await op.fill('#distance', '1');
  await op.fill('#direction', '0');
  assert.match(await op.textContent('#direction-help'), /0° pushes towards \+x/);
  await op.waitForFunction(() => document.querySelector('.map-svg .push-preview').style.display !== 'none', null, { timeout: 5000 });
  const onMap = (pt) => op.evaluate(([x, y]) => {
    const g = window.nanopush.image2d.geometry();
    const e = window.nanopush.image2d.extent();
    return [g.x + ((x - e.x_offset) / e.x_real) * g.w, g.y + g.h - ((y - e.y_offset) / e.y_real) * g.h];
  }, pt);
  const [a0, b0] = [await onMap([p0.x, p0.y]), await onMap([p0.x + 1e-6, p0.y])];
  const previewAt = () => op.$eval('.map-svg .push-preview line', (l) => ['x1', 'y1', 'x2', 'y2'].map((a) => Number(l.getAttribute(a))));
  try {
    await op.waitForFunction(([b]) => Math.abs(Number(document.querySelector('.map-svg .push-preview line').getAttribute('x2')) - b[0]) < 1, [b0], { timeout: 5000 });
  } catch {
    assert.fail(`the preview ends at ${await previewAt()}, not ${b0}`);
  }
  const line = await previewAt();
  assert.ok(Math.hypot(line[0] - a0[0], line[1] - a0[1]) < 1 && Math.hypot(line[2] - b0[0], line[3] - b0[1]) < 1, `preview ${line} vs ${a0} → ${b0}`);
  await op.click('#push-btn');
  await waitText(op, '#reply-push', /^push accepted: running$/, 30000);
  // During the push the particle's ring follows the controller's estimate, not its start; the
  // progress is against the plan's 1 µm.
  await op.waitForFunction(() => {
    const e = window.nanopush.session.state.tip?.estimate;
    return window.nanopush.session.state.push && e && e[0] > window.nanopush.session.state.push.path[0][0] + 0.3e-6;
  }, null, { timeout: 60000, polling: 20 });
  // Read in the frame the ring was drawn in (a probe drawn after the map's live view), with the
  // estimate it was drawn from.
  const live = await op.evaluate(() => new Promise((res) => {
    const f = window.nanopush.frames;
    const moved = f.views.find((v) => v.name === 'map-live');
    const n0 = moved.frames;
    const probe = f.register('probe', () => {
      if (moved.frames === n0) {
        probe.mark();
        return;
      }
      const ring = document.querySelector('.map-dot.pushed');
      const m = /translate\(([-\d.]+)px, ([-\d.]+)px\)/.exec(ring.style.transform);
      res({ ring: m && [Number(m[1]), Number(m[2])], hidden: ring.hidden, est: window.nanopush.session.state.tip.estimate, progress: document.querySelector('#push-progress').textContent, max: document.querySelector('#push-bar').max });
    });
    probe.mark();
  }));
  assert.equal(live.hidden, false, 'the pushed particle is drawn');
  const want = await onMap(live.est);
  assert.ok(Math.hypot(live.ring[0] - want[0], live.ring[1] - want[1]) < 1, `ring at ${live.ring}, estimate at ${want}`);
  assert.ok(Math.hypot(live.ring[0] - a0[0], live.ring[1] - a0[1]) > 10, 'moved from where the push started');
  assert.match(live.progress, /^0\.\d\d of 1\.00 µm/, live.progress);
  assert.ok(Math.abs(live.max - 1) < 0.01, `the bar's end is the plan's 1 µm: ${live.max}`);
  const text = await waitText(op, '#lastrun', /^push of #1/, 60000);
  assert.match(text, /push of #1 ok/, text);
  assert.match(await op.textContent('#log'), /push of #1 ok.*record push-/, 'the log names the record');
  assert.match(await op.textContent('#log'), /strategy for #1: β = \d+°, read on the (push|pull) side, xy control/, 'the chosen strategy is said when the push starts');
  assert.equal(await op.textContent('#reply-push'), 'push ended: ok');
  const after = await getJson(srv.base, '/api/status');
  const p1 = after.particles.find((p) => p.id === 1);
  assert.ok(Math.abs(p1.x - p0.x - 1e-6) < 0.1e-6, `moved from ${p0.x} to ${p1.x}`);
  const s = await state(op);
  assert.ok(Math.abs(s.particles.find((p) => p.id === 1).x - p1.x) < 1e-12, 'the page shows where the server says');
  assert.equal(s.stale, true, 'the scan is stale after the push');
  assert.equal(await op.isVisible('#img-stale'), true);
  // Forces in nN, with the strategy's set point (26 nN in this scene) on the plots.
  assert.match(await op.textContent('#chart-force'), /tip force.*set point/s);
  assert.ok(Math.abs((await op.evaluate(() => window.nanopush.charts.setPointN)) - 26e-9) < 1e-15);
  // The records show the run's outcome.
  await waitText(op, '#records', /ok/, 10000);
  assert.deepEqual(op.errors, []);
  await shot(op, '02-operator-pushed');
});

test('a viewer joining after the push sees the moved particle and the scan', async () => {
  const status = await getJson(srv.base, '/api/status');
  const x = status.particles.find((p) => p.id === 1).x;
  const v = await newPage(browser);
  await v.goto(srv.base + '/');
  await ready(v);
  // The moved particle first: where the server has it, not the scene file's position.
  try {
    await v.waitForFunction((want) => Math.abs(window.nanopush.session.state.particles.find((p) => p.id === 1).x - want) < 1e-12, x, { timeout: 10000 });
  } catch {
    const shown = await v.evaluate(() => window.nanopush.session.state.particles.find((p) => p.id === 1).x);
    assert.fail(`the late viewer shows particle 1 at x = ${shown} m, the server has ${x} m`);
  }
  await v.waitForFunction(() => /32 of 32 lines/.test(document.querySelector('#image2d svg')?.getAttribute('aria-label') ?? ''), null, { timeout: 20000 });
  const s = await state(v);
  assert.ok(Math.abs(s.particles.find((p) => p.id === 1).x - x) < 1e-12, `viewer shows ${s.particles[0].x}, server ${x}`);
  assert.equal(s.scan.lines, 32);
  assert.equal(s.stale, true);
  assert.equal(await v.isVisible('#img-stale'), true);
  // Its 3D view, opened now (three.js loaded then), has the particle where it is now.
  await v.click('#toggle-3d');
  await v.waitForFunction(() => window.nanopush.app.view.loaded, null, { timeout: 20000 });
  const mx = await v.evaluate(() => window.nanopush.view.particleCentre(1).x);
  assert.ok(Math.abs(mx - x * 1e6) < 1e-6);
  // "Centre on particle" uses the moved position (an operator page opened now).
  const op2 = await newPage(browser);
  await op2.goto(srv.url);
  await ready(op2);
  // (Its scan form is disabled: the first operator holds the lease. The form is centred on the
  // particle as the server has it.)
  await op2.waitForFunction((v) => document.querySelector('#scan-x').value === v, (x * 1e6).toFixed(2), { timeout: 5000 });
  assert.deepEqual(v.errors, []);
  assert.deepEqual(op2.errors, []);
  await shot(v, '03-late-viewer');
  await v.context().close();
  await op2.context().close();
});

test('a push that never starts shows its failure code, reason and record', async () => {
  await pushBy(op, 60, 0); // a target 60 µm away, off the stage
  try {
    await waitText(op, '#log', /push of #1 failed: plan/, 30000);
  } catch (e) {
    assert.deepEqual(op.errors, [], 'the failure was not shown; the page threw');
    throw e;
  }
  const text = await waitText(op, '#lastrun', /failed/, 5000);
  assert.match(text, /push of #1 failed: plan: particle 1: target \(101\.00, 30\.00\) µm is outside the stage/, text);
  assert.match(text, /it never started \(no record\)/, text);
  assert.equal(await op.getAttribute('#lastrun', 'class'), 'lastrun bad');
  assert.match(await op.textContent('#log'), /push of #1 failed: plan/);
  assert.deepEqual(op.errors, [], 'no exception in the page');
  await shot(op, '04-failed-push');
});

test('a viewer cannot command; sees the operator\'s push path, not its form\'s', async () => {
  const v = await newPage(browser);
  await v.goto(srv.base + '/');
  await ready(v);
  for (const sel of ['#push-fs', '#scan-fs', '#take-lease', '#push-btn', '#scan-btn']) {
    assert.equal(await v.$eval(sel, (e) => e.disabled || e.closest('fieldset')?.disabled), true, `${sel} disabled for a viewer`);
  }
  // Stop stays pressable, to say why it cannot act.
  assert.equal(await v.getAttribute('#stop-btn', 'aria-disabled'), 'true');
  await v.click('#stop-btn', { force: true }); // (aria-disabled: Playwright would wait for it)
  assert.match(await v.textContent('#reply-stop'), /^Stop not sent: viewer connection/);
  // A viewer gets no forms it cannot use, only the reason.
  assert.equal(await v.isVisible('#push-form'), false);
  assert.equal(await v.isVisible('#scan-form'), false);
  assert.match(await v.textContent('#why'), /Viewer connection/);
  // The viewer's own form would preview 5 µm along +x: it must not be drawn, on the map or in 3D.
  assert.equal(await v.$eval('.map-svg .push-preview', (e) => e.style.display), 'none');
  await v.click('#toggle-3d');
  await v.waitForFunction(() => window.nanopush.app.view.loaded, null, { timeout: 20000 });
  assert.equal(await v.evaluate(() => window.nanopush.view.marks.preview.visible), false);
  const from = (await getJson(srv.base, '/api/status')).particles.find((p) => p.id === 1);
  await pushBy(op, 2, 90);
  await v.waitForFunction(() => window.nanopush.view.marks.pushPath.visible, null, { timeout: 30000 });
  const pts = await v.evaluate(() => window.nanopush.view.marks.pathPoints);
  const end = pts[pts.length - 1];
  assert.ok(Math.abs(end[0] - from.x * 1e6) < 0.1 && Math.abs(end[1] - (from.y * 1e6 + 2)) < 0.1, `path ends at ${end}`);
  assert.equal(await v.evaluate(() => window.nanopush.view.marks.preview.visible), false);
  assert.match(await v.textContent('#push-now'), /Pushing #1 \(client \d+\)/);
  await shot(v, '05-viewer-sees-push');
  await waitText(v, '#lastrun', /^push of #1 ok/, 60000);
  assert.equal(await v.evaluate(() => window.nanopush.view.marks.pushPath.visible), false, 'the path goes when the push ends');
  assert.deepEqual(v.errors, []);
  await v.context().close();
});

test('the 2D image\'s axes, scale bar and profile hold the physical lengths', async () => {
  const s = (await state(op)).scan;
  const g = await op.evaluate(() => window.nanopush.image2d.geometry());
  // x ticks: metres per pixel times the image width is the scan's width.
  const ticks = await op.$$eval('#image2d text.xtick', (ts) => ts.map((t) => ({ x: Number(t.getAttribute('x')), m: Number(t.dataset.valueM), label: t.textContent })));
  assert.ok(ticks.length >= 3, JSON.stringify(ticks));
  const a = ticks[0];
  const b = ticks[ticks.length - 1];
  const perPx = (b.m - a.m) / (b.x - a.x);
  assert.ok(Math.abs(perPx * g.w - s.x_real) / s.x_real < 0.01, `${perPx * g.w} vs ${s.x_real}`);
  assert.equal(g.unit.name, 'µm', 'a 10 µm scan is labelled in µm');
  // The stage's frame: the labels are stage coordinates, within the scan's stage span.
  assert.equal(Number(b.label), Number((b.m * 1e6).toPrecision(6)));
  assert.ok(a.m >= s.x_offset && b.m <= s.x_offset + s.x_real + 1e-12 && a.m > 1e-6, `ticks ${a.label}…${b.label} over a scan from ${s.x_offset}`);
  assert.deepEqual(await op.$$eval('#image2d .axis-label', (ls) => ls.map((l) => l.textContent).slice(0, 2)), ['stage x (µm)', 'stage y (µm)']);
  const yt = await op.$$eval('#image2d text.ytick', (ts) => ts.length);
  assert.ok(yt >= 3);
  assert.match(await op.textContent('#image2d'), /height \(nm\)/);
  // The scale bar.
  const bar = await op.$eval('#image2d g.scalebar', (e) => ({ m: Number(e.dataset.lengthM), w: Number(e.querySelector('.scalebar-bar').getAttribute('width')), label: e.querySelector('text').textContent }));
  assert.ok(Math.abs((bar.w / g.w) * s.x_real - bar.m) / bar.m < 0.01, JSON.stringify(bar));
  assert.equal(bar.label, `${Number((bar.m * 1e6).toPrecision(6))} µm`);
  // A line profile dragged from (10 %, 20 %) to (70 %, 60 %) of the image.
  const box = await op.$eval('#image2d', (e) => { const r = e.getBoundingClientRect(); return { x: r.left, y: r.top }; });
  const at = (fx, fy) => [box.x + g.x + fx * g.w, box.y + g.y + g.h - fy * g.h];
  await op.mouse.move(...at(0.1, 0.2));
  await op.mouse.down();
  await op.mouse.move(...at(0.4, 0.4), { steps: 4 });
  await op.mouse.move(...at(0.7, 0.6), { steps: 4 });
  await op.mouse.up();
  await op.waitForFunction(() => window.nanopush.image2d.profile !== null);
  const prof = await op.evaluate(() => { const p = window.nanopush.image2d.profile; return { lengthM: p.lengthM, unit: p.unit, n: p.distances.length, last: p.distances[p.distances.length - 1] }; });
  const expected = Math.hypot(0.6 * s.x_real, 0.4 * s.y_real);
  assert.ok(Math.abs(prof.lengthM - expected) / expected < 0.01, `${prof.lengthM} vs ${expected}`);
  assert.ok(Math.abs(prof.last - expected * 1e6) < 0.01 * expected * 1e6, 'the profile plot ends at the line length');
  assert.match(await op.textContent('#profile-info'), new RegExp(`profile length ${(expected * 1e6).toPrecision(4).slice(0, 3)}`));
  await op.waitForSelector('#profile canvas', { timeout: 10000 }); // the profile plot is drawn
  // One frame: the axes, the cursor readout, the tip readout and the target fields agree.
  const axisAt = async (px, py) => op.evaluate(([qx, qy]) => {
    const lin = (sel, attr, q) => {
      const ts = [...document.querySelectorAll(sel)].map((t) => [Number(t.getAttribute(attr)), Number(t.textContent)]);
      const [p0, p1] = [ts[0], ts[ts.length - 1]];
      return p0[1] + ((q - p0[0]) / (p1[0] - p0[0])) * (p1[1] - p0[1]);
    };
    // (the y ticks' text sits 4 px below its tick)
    return [lin('#image2d text.xtick', 'x', qx), lin('#image2d text.ytick', 'y', qy + 4)];
  }, [px, py]);
  const [fx, fy] = [0.31, 0.57];
  await op.mouse.move(...at(fx, fy));
  const cur = /^stage x (\d+\.\d{3}) µm, y (\d+\.\d{3}) µm, height -?\d+\.\d+ nm$/.exec(await op.textContent('#img-cursor'));
  assert.ok(cur, await op.textContent('#img-cursor'));
  const ax = await axisAt(g.x + fx * g.w, g.y + g.h - fy * g.h);
  const umPerPx = (s.x_real * 1e6) / g.w;
  assert.ok(Math.abs(Number(cur[1]) - ax[0]) < umPerPx && Math.abs(Number(cur[2]) - ax[1]) < umPerPx, `readout ${cur[1]}, ${cur[2]} vs axes ${ax}`);
  await op.mouse.click(...at(fx, fy)); // not on a particle: the push target
  const tx = Number(await op.inputValue('#to-x'));
  const ty = Number(await op.inputValue('#to-y'));
  assert.ok(Math.abs(tx - Number(cur[1])) < 0.011 && Math.abs(ty - Number(cur[2])) < 0.011, `target ${tx}, ${ty} vs readout ${cur[1]}, ${cur[2]}`);
  await op.check('input[name=mode][value=by]');
  const tipAt = await op.evaluate(() => {
    const t = document.querySelector('.map-dot.tip');
    const m = /translate\(([-\d.]+)px, ([-\d.]+)px\)/.exec(t.style.transform);
    return [Number(m[1]), Number(m[2])];
  });
  const tipAx = await axisAt(...tipAt);
  const tip = /^tip \((\d+\.\d{3}), (\d+\.\d{3})\) µm/.exec(await waitText(op, '#tipinfo', /^tip \(/, 5000));
  assert.ok(Math.abs(Number(tip[1]) - tipAx[0]) < 2 * umPerPx && Math.abs(Number(tip[2]) - tipAx[1]) < 2 * umPerPx, `tip readout ${tip[1]}, ${tip[2]} vs drawn at axes ${tipAx}`);
  await shot(op, '06-image-profile');
});

test('a viewer back mid-scan gets the whole scan; Stop ends a push at once', async () => {
  await op.fill('#scan-size', '16');
  await op.fill('#scan-px', '512');
  // A viewer loses its connection while the lines of a 512² scan stream and joins again
  // mid-scan: it gets the lines so far at once (none blank below the newest, its progress the
  // operator's), ends with every line, and has the scan on screen for what follows.
  const late = await newPage(browser);
  await late.goto(srv.base + '/');
  await ready(late);
  await op.click('#scan-btn');
  await late.waitForFunction(() => window.nanopush.session.state.scan?.xres === 512 && window.nanopush.session.state.scan.lines >= 8, null, { timeout: 60000, polling: 10 });
  await late.evaluate(() => window.nanopush.app.conn.ws.close());
  await ready(late);
  const opLines = await op.evaluate(() => window.nanopush.session.state.scan.lines);
  await late.waitForFunction((n) => window.nanopush.session.state.scan?.lines >= n, opLines, { timeout: 10000, polling: 10 });
  const joined = await late.evaluate(() => {
    const sc = window.nanopush.session.state.scan;
    const top = sc.received.lastIndexOf(1);
    return { xres: sc.xres, done: sc.done, lines: sc.lines, blank: sc.received.slice(0, top + 1).filter((r) => !r).length };
  });
  assert.equal(joined.done, false, 'joined again while the scan ran');
  assert.equal(joined.blank, 0, `no blank rows below the newest: ${JSON.stringify(joined)}`);
  try {
    await late.waitForFunction((n) => Number(/line (\d+)\/512/.exec(document.querySelector('#scan-progress').textContent)?.[1]) >= n, opLines, { timeout: 5000, polling: 10 });
  } catch {
    assert.fail(`progress "${await late.textContent('#scan-progress')}" with the operator at line ${opLines}, ${joined.lines} lines here`);
  }
  await op.waitForFunction(() => window.nanopush.session.state.scan?.xres === 512 && window.nanopush.session.state.scan.done, null, { timeout: 60000 });
  await late.waitForFunction(() => /512 of 512 lines/.test(document.querySelector('#image2d svg')?.getAttribute('aria-label') ?? ''), null, { timeout: 20000 });
  const got = await late.evaluate(() => { const sc = window.nanopush.session.state.scan; return { lines: sc.lines, unfilled: sc.received.filter((r) => !r).length, nan: sc.heights.filter((v) => !Number.isFinite(v)).length }; });
  assert.deepEqual(got, { lines: 512, unfilled: 0, nan: 0 }, `joined at ${JSON.stringify(joined)}`);
  console.log(`# the viewer joined scan 512² at ${JSON.stringify(joined)}`);
  assert.deepEqual(late.errors, []);
  await late.context().close();
  // Three presses, each during a push (the tip moving, telemetry flowing, the 3D view redrawn):
  // each is answered `ok`, the push ends `stopped` and the page goes back to idle. How fast the
  // reply shows is a measurement, not a test (this machine is shared): it is printed here, and
  // `node e2e/bench.js` measures it for docs/benchmarks.md ("The Nano Visulator in a browser").
  const runs = [];
  for (let k = 0; k < 3; k++) {
    await pushBy(op, 3, k % 2 ? 0 : 180);
    await op.waitForFunction(() => !['idle', 'scanning'].includes(window.nanopush.session.state.phase), null, { timeout: 30000 });
    runs.push(await timedStop(op));
    const text = await waitText(op, '#lastrun', /^push of #1 stopped/, 60000);
    // A stop is no failure: said once ("stopped: …", not "failed: stopped: …"), in a neutral colour.
    assert.match(text, /^push of #1 stopped: stop requested by the operator, particle left at/);
    assert.equal(await op.getAttribute('#lastrun', 'class'), 'lastrun neutral');
    await op.waitForFunction(() => window.nanopush.session.state.phase === 'idle', null, { timeout: 30000 });
    await op.evaluate(() => { document.querySelector('#lastrun').textContent = ''; });
  }
  console.log(`# stop latency (ms, in the page / from outside): ${runs.map((r) => `${r.inPage.toFixed(0)}/${r.outside}`).join(', ')}`);
  await shot(op, '07-stopped-512');
});

test('at 1280×720 and 1600×1000 the image, Stop and the lease stay in view', async () => {
  for (const [width, height] of [[1280, 720], [1600, 1000]]) {
    const p = await newPage(browser, { width, height });
    await p.goto(srv.url);
    await ready(p);
    // Every element measured below drawn first (the image's parts come with its next frame).
    await p.waitForFunction(() => window.nanopush.session.state.scan?.done
      && ['#image2d text.xtick', '#image2d .axis-label', '#image2d g.scalebar', '.profile-box'].every((q) => document.querySelector(q)), null, { timeout: 20000 });
    const rects = () => p.evaluate(() => {
      const r = (s) => { const e = document.querySelector(s); if (!e) throw new Error(`${s} is not on the page`); const b = e.getBoundingClientRect(); return { top: Math.round(b.top), bottom: Math.round(b.bottom), left: Math.round(b.left), right: Math.round(b.right) }; };
      return {
        image: r('#image2d'), xlabel: r('#image2d .axis-label'), scalebar: r('#image2d g.scalebar'), profile: r('.profile-box'),
        stop: r('#stop-btn'), take: r('#take-lease'), release: r('#release-lease'), push: r('#push-fs'),
        scroll: document.documentElement.scrollHeight, inner: window.innerHeight, innerW: window.innerWidth,
      };
    });
    const a = await rects();
    for (const k of ['image', 'xlabel', 'scalebar', 'profile', 'stop', 'take', 'release']) {
      assert.ok(a[k].top >= 0 && a[k].bottom <= a.inner && a[k].right <= a.innerW, `${width}×${height}: ${k} out of view: ${JSON.stringify(a[k])}`);
    }
    assert.ok(a.scroll <= a.inner, `${width}×${height}: the page scrolls (${a.scroll} px)`);
    assert.ok(a.image.bottom - a.image.top >= 300, `${width}×${height}: the image is ${a.image.bottom - a.image.top} px high`);
    // The cursor in the image (a long readout), a push starting and ending: nothing moves.
    const g = await p.evaluate(() => window.nanopush.image2d.geometry());
    await p.mouse.move(a.image.left + g.x + g.w * 0.5, a.image.top + g.y + g.h * 0.5);
    await p.waitForFunction(() => /height/.test(document.querySelector('#img-cursor').textContent) && !/x –/.test(document.querySelector('#img-cursor').textContent));
    assert.deepEqual(await rects(), a, `${width}×${height}: the cursor moved the layout`);
    // The readouts and the map's help whole, the cursor on the map and the tip's numbers shown.
    await waitText(p, '#tipinfo', /^tip \(/, 5000);
    assert.deepEqual(await clippedIn(p, ['.map-head', '.readouts', '#map-help', '.profile-box h3', '.ctl']), [], `${width}×${height}, the cursor on the map`);
    if (width === 1280) {
      await pushBy(op, 1, 90);
      await p.waitForFunction(() => !document.querySelector('#push-now').hidden, null, { timeout: 30000 });
      assert.deepEqual(await rects(), a, 'a push starting moved the layout');
      assert.deepEqual(await clippedIn(p, ['.ctl']), [], 'the push running, whole');
      await waitText(p, '#lastrun', /^push of #1/, 60000);
      assert.deepEqual(await rects(), a, 'a push ending moved the layout');
      // The last run's line whole, no scroll box; axe finds nothing with the log filled.
      assert.deepEqual(await clippedIn(p, ['.ctl', '.readouts', '#map-help']), [], 'the last run, whole');
      const v = await axe(p);
      assert.deepEqual(v, [], JSON.stringify(v, null, 1));
      await shot(p, '12-operator-1280x720');
    }
    assert.deepEqual(p.errors, []);
    await p.context().close();
  }
});

test('keyboard only: a particle and a push target picked, a profile drawn', async () => {
  await op.waitForFunction(() => window.nanopush.session.hasLease);
  await op.evaluate(() => document.activeElement?.blur());
  let tabs = 0;
  while (!(await op.evaluate(() => document.activeElement?.classList.contains('map-svg'))) && tabs < 100) {
    await op.keyboard.press('Tab');
    tabs++;
  }
  assert.ok(tabs < 100, 'the map is reached by Tab');
  const sel0 = await op.evaluate(() => window.nanopush.app.controls.selected);
  await op.keyboard.press(']');
  const sel1 = await op.evaluate(() => window.nanopush.app.controls.selected);
  const n = await op.evaluate(() => window.nanopush.session.state.particles.length);
  if (n > 1) assert.notEqual(sel1, sel0, '] selects the next particle');
  assert.equal(await op.inputValue('#particle'), String(sel1));
  // The keyboard's pick is said to a screen reader.
  await waitText(op, '#announce', new RegExp(`^particle #${sel1} selected, at \\(\\d+\\.\\d\\d, \\d+\\.\\d\\d\\) µm$`), 5000);
  // From the particle, 5 steps right (1 % of the image each) and Enter: the target.
  const cur0 = await op.evaluate(() => window.nanopush.map.cursor);
  for (let k = 0; k < 5; k++) await op.keyboard.press('ArrowRight');
  await op.keyboard.press('Shift+ArrowUp');
  await op.keyboard.press('Enter');
  const ext = await op.evaluate(() => window.nanopush.image2d.extent());
  const clamp = (v, lo, span) => Math.min(lo + span, Math.max(lo, v));
  const want = [clamp(cur0[0] + 0.05 * ext.x_real, ext.x_offset, ext.x_real) * 1e6, clamp(cur0[1] + 0.1 * ext.y_real, ext.y_offset, ext.y_real) * 1e6];
  assert.ok(cur0[0] >= ext.x_offset && cur0[0] <= ext.x_offset + ext.x_real, 'the cursor starts inside the image');
  assert.ok(Math.abs(Number(await op.inputValue('#to-x')) - want[0]) < 0.011, `${await op.inputValue('#to-x')} vs ${want[0]}`);
  assert.ok(Math.abs(Number(await op.inputValue('#to-y')) - want[1]) < 0.011, `${await op.inputValue('#to-y')} vs ${want[1]}`);
  assert.equal(await op.isChecked('input[name=mode][value=to]'), true, 'the form switched to "to target"');
  await waitText(op, '#announce', /^push target \(\d+\.\d\d, \d+\.\d\d\) µm$/, 5000);
  await op.waitForFunction(() => document.querySelector('.map-svg .target').style.display !== 'none', null, { timeout: 5000 }); // the target is marked on the map
  assert.equal(await op.evaluate(() => document.activeElement?.classList.contains('map-svg')), true, 'the focus stays on the map');
  // The line profile by keyboard.
  await op.keyboard.press('s');
  for (let k = 0; k < 3; k++) await op.keyboard.press('Shift+ArrowLeft');
  await op.keyboard.press('e');
  await op.waitForFunction(() => window.nanopush.image2d.profile !== null, null, { timeout: 5000 });
  assert.match(await op.textContent('#img-cursor'), /height/);
  await shot(op, '13-keyboard-target');
  await op.check('input[name=mode][value=by]');
});

test('a phone (390×844): no sideways scroll, controls after the image', async () => {
  const p = await newPage(browser, { width: 390, height: 844 });
  await p.goto(srv.url);
  await ready(p);
  await p.waitForFunction(() => window.nanopush.image2d.frame.frames >= 1, null, { timeout: 20000 });
  const w = await p.evaluate(() => ({ scroll: document.documentElement.scrollWidth, inner: window.innerWidth }));
  assert.ok(w.scroll <= w.inner, `page ${w.scroll} px wide in a ${w.inner} px viewport`);
  const order = await p.evaluate(() => {
    const top = (s) => document.querySelector(s).getBoundingClientRect().top + window.scrollY;
    return { image: top('#image2d'), controls: top('#ctl-h'), charts: top('#charts-h') };
  });
  assert.ok(order.image < order.controls && order.controls < order.charts, JSON.stringify(order));
  for (const sel of ['#take-lease', '#push-btn', '#scan-btn', '#stop-btn']) {
    const el = await p.$(sel);
    await el.scrollIntoViewIfNeeded();
    const hit = await el.evaluate((e) => {
      const r = e.getBoundingClientRect();
      const h = document.elementFromPoint(r.left + r.width / 2, r.top + r.height / 2);
      return { ok: h === e || e.contains(h), right: r.right, inner: window.innerWidth };
    });
    assert.ok(hit.ok && hit.right <= hit.inner, `${sel} reachable: ${JSON.stringify(hit)}`);
  }
  // Nothing cut off: the controls, the readouts, the map's help, a profile's numbers, the last run.
  await waitText(p, '#lastrun', /push of #1/, 10000);
  await p.evaluate(() => {
    const i = window.nanopush.image2d;
    const e = i.extent();
    i.profileEnd('start', e.x_offset + 0.1 * e.x_real, e.y_offset + 0.5 * e.y_real);
    i.profileEnd('end', e.x_offset + 0.9 * e.x_real, e.y_offset + 0.5 * e.y_real);
  });
  await waitText(p, '#profile-info', /^profile length/, 5000);
  assert.deepEqual(await clippedIn(p, ['.map-head', '.readouts', '#map-help', '.profile-box h3', '.ctl']), []);
  const v = await axe(p);
  assert.deepEqual(v, [], JSON.stringify(v, null, 1));
  await p.evaluate(() => window.scrollTo(0, 0));
  await shot(p, '08-phone');
  assert.deepEqual(p.errors, []);
  await p.context().close();
});

test('the monitoring view is read-only, shows the instrument, passes axe', async () => {
  const m = await newPage(browser, { width: 1280, height: 800 });
  await m.goto(srv.base + '/?view=monitor');
  await waitText(m, '#m-phase', /idle|scanning|\w+/, 10000);
  await waitText(m, '#m-conn', /live/, 10000);
  assert.equal(await m.$$eval('button, input, select', (e) => e.length), 0, 'no controls');
  assert.match(await m.textContent('#m-loop'), /ticks/);
  assert.match(await m.textContent('#m-clients'), /^\d+$/);
  assert.deepEqual(m.errors, []);
  const v = await axe(m);
  assert.deepEqual(v, [], JSON.stringify(v, null, 1));
  await shot(m, '09-monitor');
  await m.context().close();
});

test('with a haptic link the panel shows it and the lease holder can engage', async () => {
  const hs = await startServer({ haptic: 'sim', webDir: process.env.E2E_WEB_DIR || WEB });
  try {
    const p = await newPage(browser);
    await p.goto(`${hs.base}/?token=${TOKEN}`);
    await ready(p);
    await p.waitForSelector('#haptic-panel', { state: 'visible', timeout: 20000 });
    await waitText(p, '#hap-link', /^up$/, 20000);
    await p.waitForSelector('#chart-hap canvas', { timeout: 10000 });
    // The device's fault counters, from /api/status every 2 s while the panel shows.
    const dev = await waitText(p, '#hap-device', /faults: none|faults:/, 8000);
    assert.match(dev, /^(\d+(\.\d+)? k?Hz · )?faults: /, dev);
    assert.match(await p.getAttribute('#hap-device', 'class'), /^(|warn|bad)$/);
    // The scales in force: the scene's default, inside the device's region.
    await waitText(p, '#hap-scales', /^10 nm\/mm, 1\.000 N pull-off, felt \d+ N\/m$/, 8000);
    // The monitor shows the same line.
    const m = await newPage(browser, { width: 1280, height: 800 });
    await m.goto(hs.base + '/?view=monitor');
    await waitText(m, '#m-hapdev', /faults: none|faults:/, 8000);
    assert.deepEqual(m.errors, []);
    await m.context().close();
    assert.equal(await p.$eval('#hap-fs', (e) => e.disabled), true, 'no lease: no haptic controls');
    // By keyboard: Enter on "Take lease" (disabled once taken) hands the focus on, not to the page.
    await p.focus('#take-lease');
    await p.keyboard.press('Enter');
    await p.waitForFunction(() => !document.querySelector('#hap-fs').disabled);
    assert.equal(await p.evaluate(() => document.activeElement?.id), 'release-lease');
    // The scales in force (the scene's), then as set: shown and in the Events log.
    await waitText(p, '#hap-scales', /^10 nm\/mm, 1\.000 N pull-off/, 8000);
    await p.fill('#hap-nm', '20');
    await p.click('#hap-scale');
    await waitText(p, '#reply-haptic', /^done$/, 10000);
    await waitText(p, '#hap-scales', /^20 nm\/mm/, 8000);
    await waitText(p, '#log', /haptic scales now 20 nm\/mm/, 5000);
    await p.click('#hap-engage');
    await waitText(p, '#reply-haptic', /^done$/, 10000);
    await waitText(p, '#hap-phase', /finding the surface|rising to the parking height|waiting for the force|force ramping in|engaged/, 20000);
    await shot(p, '11-haptic');
    // The link lost (the bridge frozen with SIGSTOP, so it is not restarted) and back: both in
    // the Events log, the losses counted, Engage disabled while it is down.
    const { pid } = (await getJson(hs.base, '/api/status')).haptic;
    assert.ok(pid > 0, 'the bridge runs');
    process.kill(pid, 'SIGSTOP');
    try {
      await waitText(p, '#hap-link', /^down$/, 20000);
      await waitText(p, '#log', /haptic link down/, 5000);
      assert.equal(await p.$eval('#hap-engage', (e) => e.disabled), true, 'no Engage without a link');
      assert.match(await p.getAttribute('#hap-engage', 'title'), /link is down/);
      await waitText(p, '#hap-downs', /^[1-9]\d*$/, 8000);
    } finally {
      process.kill(pid, 'SIGCONT');
    }
    await waitText(p, '#hap-link', /^up$/, 20000);
    await waitText(p, '#log', /haptic link up \(\d+ link loss/, 5000);
    await p.waitForFunction(() => !document.querySelector('#hap-engage').disabled, null, { timeout: 5000 });
    await shot(p, '14-haptic-link-lost-and-back');
    assert.deepEqual(p.errors, []);
    await p.context().close();
  } finally {
    await hs.stop();
  }
});

test('served unbuilt (no web/dist), the page and the server say how to build', async () => {
  const dir = mkdtempSync(join(tmpdir(), 'nanopush-web-bare-'));
  const web = process.env.E2E_WEB_DIR || WEB;
  symlinkSync(join(web, 'index.html'), join(dir, 'index.html'));
  symlinkSync(join(web, 'src'), join(dir, 'src'));
  const bare = await startServer({ webDir: dir });
  try {
    const p = await newPage(browser);
    await p.goto(`${bare.base}/?token=${TOKEN}`);
    const text = await waitText(p, '#boot-error', /npm run build/, 15000);
    assert.match(text, /could not start/);
    assert.equal(await p.isVisible('#boot-error'), true);
    assert.doesNotMatch(await p.textContent('#st-conn'), /starting/);
    assert.match(bare.log(), /web client is not built.*npm run build/);
    await shot(p, '10-not-built');
    await p.context().close();
  } finally {
    await bare.stop();
    rmSync(dir, { recursive: true, force: true });
  }
});
