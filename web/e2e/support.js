// Helpers for the browser end-to-end tests: start the real `nanopush serve` on a free port with
// a quick scene, and a headless Chromium (Debian's, driven by playwright-core) with SwiftShader.
import { spawn, spawnSync } from 'node:child_process';
import { mkdtempSync, readFileSync, writeFileSync, mkdirSync, existsSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

export const WEB = resolve(dirname(fileURLToPath(import.meta.url)), '..');
export const ROOT = resolve(WEB, '..');
export const TOKEN = 'e2e-browser-operator';
export const ARTIFACTS = join(WEB, 'test-results');

/** The server binary: $NANOPUSH_BIN, else $CARGO_TARGET_DIR/debug, else target/debug. */
export function serverBin() {
  if (process.env.NANOPUSH_BIN) return process.env.NANOPUSH_BIN;
  const target = process.env.CARGO_TARGET_DIR ? resolve(ROOT, process.env.CARGO_TARGET_DIR) : join(ROOT, 'target');
  const bin = join(target, 'debug', 'nanopush');
  if (!existsSync(bin)) throw new Error(`${bin} is missing: build it first (cargo build --bins), or set NANOPUSH_BIN`);
  return bin;
}

/** The chromium executable: $CHROMIUM, else /usr/bin/chromium (Debian's `chromium`). */
export function chromiumPath() {
  const p = process.env.CHROMIUM || '/usr/bin/chromium';
  if (!existsSync(p)) throw new Error(`${p} is missing: install Debian's chromium (make setup), or set CHROMIUM`);
  return p;
}

/** The quick scene's default scan: 16 µm around particle 1, 32 pixels. */
export const FAST_SCAN = Object.freeze({ centre_x_um: 40.0, centre_y_um: 32.0, size_um: 16.0, pixels: 32 });

/**
 * The gold-latex scene made quick, as the Rust e2e tests make it (tests/e2e/util.rs): a level
 * substrate, a low start height, fast approaches and travel, a 16 µm default scan (`scan`: another
 * `[scan]`, e.g. the full frame an assembly starts from).
 */
export function fastScene(dir, scan = FAST_SCAN) {
  let text = readFileSync(join(ROOT, 'scenes/gold-latex-500nm.toml'), 'utf8');
  text = text.replace('tilt_x_mrad = 6.0', 'tilt_x_mrad = 0.0').replace('roughness_rms_nm = 0.5', 'roughness_rms_nm = 0.0');
  // The scene writes its [strategy] out (the paper's search): these values replace its own.
  const quick = { start_height_um: '1.2', approach_speed_um_per_s: '5.0', travel_speed_um_per_s: '40.0', approach_distance_um: '0.3', dwell_ms: '2.0' };
  for (const [k, v] of Object.entries(quick)) {
    const re = new RegExp(`^${k} = .*$`, 'm');
    if (!re.test(text)) throw new Error(`the gold-latex scene has no ${k} in its [strategy]`);
    text = text.replace(re, `${k} = ${v}`);
  }
  text += `\n[scan]\n${Object.entries(scan).map(([k, v]) => `${k} = ${Number.isInteger(v) && k !== 'pixels' ? v.toFixed(1) : v}`).join('\n')}\n`;
  const path = join(dir, 'fast.toml');
  writeFileSync(path, text);
  return path;
}

/**
 * Starts `nanopush serve` (no real-time scheduling: the machine is shared) and resolves when it
 * prints its address. `extra` are more arguments; `webDir` another web client directory;
 * `haptic` the link (`none`, `sim`); `port` and `dir`: a server started again where another
 * ran (its records kept: `stop({ keep: true })` leaves the directory). `tokenFile`: named people
 * (`--token-file`, instead of the operator token); `tls`: the server's `--tls-cert`/`--tls-key`
 * ({cert, key}): then `base` is `https://…`. `scan`: the scene's `[scan]` (fastScene).
 * @returns {Promise<{url:string, addr:string, base:string, dir:string, pid:number, log:()=>string, kill:(sig:string)=>Promise<void>, stop:(o?:{keep?:boolean})=>Promise<void>}>}
 */
export async function startServer({ extra = [], webDir = WEB, haptic = 'none', port = 0, dir = null, tokenFile = null, tls = null, scan = FAST_SCAN } = {}) {
  dir = dir ?? mkdtempSync(join(tmpdir(), 'nanopush-browser-'));
  const records = join(dir, 'records');
  mkdirSync(records, { recursive: true });
  const who = tokenFile ? ['--token-file', tokenFile] : ['--operator-token', TOKEN];
  const https = tls ? ['--tls-cert', tls.cert, '--tls-key', tls.key] : [];
  const args = ['serve', '--port', String(port), '--haptic', haptic, '--no-realtime', ...who, ...https,
    '--scene', fastScene(dir, scan), '--data-dir', records, '--web-dir', webDir, '--scan-line-hz', '400', ...extra];
  // A haptic link of its own (iceoryx2 services apart from any other server on this machine).
  const env = { ...process.env, NANOPUSH_HAPTIC_NAMESPACE: `browser${process.pid}` };
  const child = spawn(serverBin(), args, { cwd: ROOT, env, stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  child.stderr.on('data', (d) => { log += d; });
  const lines = createInterface({ input: child.stdout });
  const addr = await new Promise((res, rej) => {
    const t = setTimeout(() => rej(new Error(`nanopush serve did not start within 20 s:\n${log}`)), 20000);
    child.on('exit', (code) => rej(new Error(`nanopush serve exited (${code}):\n${log}`)));
    lines.once('line', (l) => {
      clearTimeout(t);
      const m = /listening on (\S+)/.exec(l);
      if (m) res(m[1]);
      else rej(new Error(`unexpected first line ${JSON.stringify(l)}`));
    });
  });
  const base = `${tls ? 'https' : 'http'}://${addr}`;
  return {
    addr,
    base,
    url: `${base}/?token=${TOKEN}`,
    dir,
    pid: child.pid,
    log: () => log,
    /** Sends `sig` to the server (this child only) and waits until it is gone. */
    async kill(sig) {
      if (child.exitCode !== null || child.signalCode !== null) return;
      const gone = new Promise((res) => child.once('exit', res));
      child.kill(sig);
      await gone;
    },
    async stop({ keep = false } = {}) {
      if (child.exitCode === null && child.signalCode === null) {
        const gone = new Promise((res) => child.once('exit', res));
        child.kill('SIGTERM');
        const t = setTimeout(() => child.kill('SIGKILL'), 10000);
        await gone;
        clearTimeout(t);
      }
      if (!keep) rmSync(dir, { recursive: true, force: true });
    },
  };
}

/**
 * Headless Chromium with WebGL2 on SwiftShader. `home`: the HOME it runs with (whose
 * `.pki/nssdb` holds the CAs it trusts beyond the system's: `trustingCa`).
 */
export function launchBrowser({ home = null } = {}) {
  return chromium.launch({
    executablePath: chromiumPath(),
    args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox', '--disable-dev-shm-usage'],
    ...(home ? { env: { ...process.env, HOME: home } } : {}),
  });
}

/** Runs a command; throws with its output unless it succeeds. */
export function sh(cmd, args, opts = {}) {
  const r = spawnSync(cmd, args, { encoding: 'utf8', ...opts });
  if (r.error) throw new Error(`${cmd}: ${r.error.message}`);
  if (r.status !== 0) throw new Error(`${cmd} ${args.join(' ')} failed (${r.status}): ${r.stderr}${r.stdout}`);
  return r.stdout;
}

/**
 * A test CA and a certificate for 127.0.0.1 and localhost signed by it (openssl), in `dir`:
 * {ca, cert, key} (PEM files).
 */
export function testCa(dir) {
  const p = (f) => join(dir, f);
  const ec = ['-newkey', 'ec', '-pkeyopt', 'ec_paramgen_curve:P-256', '-nodes'];
  sh('openssl', ['req', '-x509', ...ec, '-keyout', p('ca.key'), '-out', p('ca.pem'), '-days', '2', '-subj', '/CN=nanopush browser test CA',
    '-addext', 'basicConstraints=critical,CA:TRUE', '-addext', 'keyUsage=critical,keyCertSign,cRLSign']);
  sh('openssl', ['req', ...ec, '-keyout', p('key.pem'), '-out', p('leaf.csr'), '-subj', '/CN=127.0.0.1']);
  writeFileSync(p('leaf.ext'), 'basicConstraints=CA:FALSE\nsubjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\nkeyUsage=critical,digitalSignature\n');
  sh('openssl', ['x509', '-req', '-in', p('leaf.csr'), '-CA', p('ca.pem'), '-CAkey', p('ca.key'), '-CAcreateserial', '-out', p('cert.pem'), '-days', '2', '-extfile', p('leaf.ext')]);
  return { ca: p('ca.pem'), cert: p('cert.pem'), key: p('key.pem') };
}

/**
 * A HOME whose NSS database (`.pki/nssdb`, where Chromium on Linux keeps the CAs a user added)
 * trusts the CA `caPem` for web sites, as a lab's admin would install its CA: made with
 * certutil (Debian's libnss3-tools).
 */
export function trustingCa(home, caPem) {
  const db = join(home, '.pki', 'nssdb');
  mkdirSync(db, { recursive: true });
  sh('certutil', ['-d', `sql:${db}`, '-N', '--empty-password']);
  sh('certutil', ['-d', `sql:${db}`, '-A', '-t', 'C,,', '-n', 'nanopush-test-ca', '-i', caPem]);
  return home;
}

/** `nanopush token add NAME --role ROLE --token-file FILE`: the token it prints once. */
export function addToken(file, name, role) {
  const out = sh(serverBin(), ['token', 'add', name, '--role', role, '--token-file', file]);
  const token = out.trim().split('\n').pop().trim();
  if (!token.startsWith('npt_')) throw new Error(`no token in: ${out}`);
  return token;
}

/** A page that collects console errors and page errors (uncaught exceptions). */
export async function newPage(browser, { width = 1600, height = 1000 } = {}) {
  const context = await browser.newContext({ viewport: { width, height } });
  const page = await context.newPage();
  page.errors = [];
  page.on('console', (m) => {
    if (m.type() === 'error') page.errors.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => page.errors.push(`pageerror: ${e.message}`));
  return page;
}

/** GET a JSON document of the server. */
export async function getJson(base, path) {
  const r = await fetch(base + path);
  if (!r.ok) throw new Error(`${path}: HTTP ${r.status}`);
  return r.json();
}

/** Saves a screenshot under web/test-results/. */
export async function shot(page, name) {
  mkdirSync(ARTIFACTS, { recursive: true });
  await page.screenshot({ path: join(ARTIFACTS, `${name}.png`) });
}

/** Runs axe-core on the page: the violations (empty when there are none). */
export async function axe(page) {
  await page.addScriptTag({ path: join(WEB, 'node_modules/axe-core/axe.min.js') });
  return page.evaluate(async () => {
    const r = await window.axe.run(document, { resultTypes: ['violations'] });
    return r.violations.map((v) => ({ id: v.id, impact: v.impact, help: v.help, nodes: v.nodes.slice(0, 5).map((n) => `${n.target.join(' ')}: ${n.failureSummary}`) }));
  });
}

/** Waits until the page's Session is connected and has the server's state. */
export async function ready(page) {
  // (`stateReceived ?? true`: so the tests also run against a page older than the `state`
  // message, to see them fail for what the page shows, not for a missing field.)
  await page.waitForFunction(() => {
    const s = window.nanopush?.session.state;
    return s?.connection === 'open' && s.client !== null && (s.stateReceived ?? true);
  }, null, { timeout: 20000 });
}

// Presses Stop as a user would (a real click) and measures until the frame that shows its
// reply: `inPage` from the pointer-down event to that frame (ms), `outside` as the test saw it.
export async function timedStop(page) {
  await page.evaluate(() => {
    window.stopTiming = {};
    document.querySelector('#stop-btn').addEventListener('pointerdown', (e) => { window.stopTiming.down = e.timeStamp; }, { once: true });
    new MutationObserver((_, obs) => {
      if (/stop sent|\bok$/.test(document.querySelector('#reply-stop').textContent)) {
        obs.disconnect();
        requestAnimationFrame(() => { window.stopTiming.shown = performance.now(); });
      }
    }).observe(document.querySelector('#reply-stop'), { childList: true, characterData: true, subtree: true });
  });
  const b = await page.$eval('#stop-btn', (e) => { const r = e.getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; });
  const t0 = Date.now();
  await page.mouse.click(...b);
  await page.waitForFunction(() => window.stopTiming.shown !== undefined, null, { timeout: 10000, polling: 5 });
  const outside = Date.now() - t0;
  const t = await page.evaluate(() => window.stopTiming);
  return { inPage: t.shown - t.down, outside };
}

/** Waits until the text of `sel` matches `re`; returns the text. */
export async function waitText(page, sel, re, timeout = 30000) {
  await page.waitForFunction(([s, src]) => new RegExp(src).test(document.querySelector(s)?.textContent ?? ''), [sel, re.source], { timeout });
  return page.textContent(sel);
}

/** Pushes the selected particle by a distance (µm) in a direction (°), through the form. */
export async function pushBy(page, distanceUm, directionDeg) {
  await page.check('input[name=mode][value=by]');
  await page.fill('#distance', String(distanceUm));
  await page.fill('#direction', String(directionDeg));
  await page.click('#push-btn');
}

/**
 * What is cut off under the elements `sels` (each, and all inside it): text ended with an
 * ellipsis, or a box smaller than what it holds that hides or scrolls the rest. [] when nothing
 * is; each entry names the element, what it shows and what it holds (px) and its start.
 */
export function clippedIn(page, sels) {
  return page.evaluate((selectors) => {
    const out = [];
    const name = (e) => `${e.tagName.toLowerCase()}${e.id ? `#${e.id}` : ''}${typeof e.className === 'string' && e.className ? `.${e.className.trim().split(/\s+/).join('.')}` : ''}`;
    for (const sel of selectors) {
      const root = document.querySelector(sel);
      if (!root) continue;
      for (const e of [root, ...root.querySelectorAll('*')]) {
        const cs = getComputedStyle(e);
        if (cs.display === 'none' || cs.visibility === 'hidden' || e.closest('[hidden]')) continue;
        const text = (e.textContent ?? '').trim().slice(0, 40);
        const wide = e.scrollWidth > e.clientWidth + 1;
        const tall = e.scrollHeight > e.clientHeight + 1;
        if (wide && cs.textOverflow === 'ellipsis') out.push(`${name(e)} ends with an ellipsis (${e.clientWidth} of ${e.scrollWidth} px): "${text}"`);
        else if (wide && ['hidden', 'clip', 'auto', 'scroll'].includes(cs.overflowX)) out.push(`${name(e)} cuts its width (${e.clientWidth} of ${e.scrollWidth} px): "${text}"`);
        if (tall && ['hidden', 'clip', 'auto', 'scroll'].includes(cs.overflowY)) out.push(`${name(e)} ${cs.overflowY === 'auto' || cs.overflowY === 'scroll' ? 'is a scroll box' : 'cuts its height'} (${e.clientHeight} of ${e.scrollHeight} px): "${text}"`);
      }
    }
    return out;
  }, sels);
}

/** The page's scripts and API requests so far: [url path]. */
export function requested(page) {
  return page.evaluate(() => performance.getEntriesByType('resource').map((r) => new URL(r.name).pathname));
}
