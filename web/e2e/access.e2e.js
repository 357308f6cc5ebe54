// Named people over HTTPS, in a real browser: the server has a certificate from a
// test CA that the browser trusts as a lab's CA is trusted (in its NSS database; no
// certificate errors ignored), and a token file of Alice (operator) and Bob (viewer). The page
// exchanges the token in its URL for an HttpOnly, SameSite=Strict, Secure cookie and removes
// the token from the address bar; a reload signs in with the cookie; everyone sees the lease
// holder by name, on the page and on the monitor. Run by `npm run e2e`.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { startServer, launchBrowser, newPage, ready, waitText, testCa, trustingCa, addToken, shot } from './support.js';

let srv;
let browser;
let scratch;
const tokens = {};

before(async () => {
  scratch = mkdtempSync(join(tmpdir(), 'nanopush-access-'));
  const tls = testCa(scratch);
  const tokenFile = join(scratch, 'tokens');
  tokens.alice = addToken(tokenFile, 'alice', 'operator');
  tokens.bob = addToken(tokenFile, 'bob', 'viewer');
  srv = await startServer({ tokenFile, tls });
  browser = await launchBrowser({ home: trustingCa(join(scratch, 'home'), tls.ca) });
});

after(async () => {
  await browser?.close();
  await srv?.stop();
  if (scratch) rmSync(scratch, { recursive: true, force: true });
});

test('over HTTPS the URL token becomes a cookie; the holder is named', async () => {
  const alice = await newPage(browser, { width: 1280, height: 720 });
  const loaded = await alice.goto(`${srv.base}/?token=${tokens.alice}`);
  assert.ok(loaded.ok(), `the page over HTTPS: ${loaded.status()}`);
  assert.ok(loaded.url().startsWith('https://'), loaded.url());
  await ready(alice);
  assert.ok(!alice.url().includes('token'), `the token left the address bar: ${alice.url()}`);
  const cookies = await alice.context().cookies();
  const c = cookies.find((k) => k.name === 'nanopush_session');
  assert.ok(c, JSON.stringify(cookies));
  assert.equal(c.httpOnly, true, 'HttpOnly');
  assert.equal(c.sameSite, 'Strict', 'SameSite=Strict');
  assert.equal(c.secure, true, 'Secure');
  assert.ok(!(await alice.evaluate(() => document.cookie)).includes('nanopush_session'), 'scripts cannot read it');
  const me = await alice.evaluate(() => ({ name: window.nanopush.session.state.name, role: window.nanopush.session.state.role }));
  assert.deepEqual(me, { name: 'alice', role: 'operator' });

  await alice.click('#take-lease');
  await alice.waitForFunction(() => window.nanopush.session.hasLease);
  await waitText(alice, '#st-lease', /^you \(alice, \d+\)$/);

  const bob = await newPage(browser, { width: 1280, height: 720 });
  await bob.goto(`${srv.base}/?token=${tokens.bob}`);
  await ready(bob);
  assert.equal(await bob.evaluate(() => window.nanopush.session.state.role), 'viewer');
  await waitText(bob, '#st-lease', /^alice \(client \d+\)$/);
  assert.match(await bob.getAttribute('#take-lease', 'title') ?? '', /alice \(client \d+\) holds the lease|Viewer connection/);

  const mon = await newPage(browser, { width: 800, height: 600 });
  await mon.goto(`${srv.base}/?view=monitor&token=${tokens.bob}`);
  await waitText(mon, '#m-lease', /^alice \(client \d+\)$/, 15000);
  assert.ok(!mon.url().includes('token'), mon.url());
  await shot(mon, 'monitor-named-lease');

  // Someone without a token (nor a cookie) is told how to sign in.
  const stranger = await newPage(browser, { width: 1280, height: 720 });
  await stranger.goto(`${srv.base}/`);
  await waitText(stranger, '#boot-error', /needs your token/, 15000);
  assert.equal(await stranger.isVisible('#boot-error'), true);

  // A reload has no token in its URL any more: the cookie signs Alice in again.
  await alice.reload();
  await ready(alice);
  assert.deepEqual(await alice.evaluate(() => ({ name: window.nanopush.session.state.name, role: window.nanopush.session.state.role })), { name: 'alice', role: 'operator' });
  assert.deepEqual(alice.errors, [], alice.errors.join('\n'));
  // The history holds no entry with the token: the one before the page is the blank tab.
  await alice.goBack();
  assert.equal(alice.url(), 'about:blank');
  assert.deepEqual(bob.errors, [], bob.errors.join('\n'));
});

test('a page signed in before a server restart is signed in after it', async () => {
  const alice = await newPage(browser, { width: 1280, height: 720 });
  await alice.goto(`${srv.base}/?token=${tokens.alice}`);
  await ready(alice);
  const before = await alice.evaluate(() => window.nanopush.session.state.instance);
  const port = Number(srv.addr.split(':').pop());
  // The same data directory: the cookies' signing key is kept there, so the cookie outlives the
  // restart.
  const { dir } = srv;
  await srv.stop({ keep: true });
  srv = await startServer({ tokenFile: join(scratch, 'tokens'), tls: { cert: join(scratch, 'cert.pem'), key: join(scratch, 'key.pem') }, port, dir });
  await alice.waitForFunction((old) => {
    const s = window.nanopush.session.state;
    return s.connection === 'open' && s.instance !== null && s.instance !== old;
  }, before, { timeout: 30000 });
  assert.deepEqual(await alice.evaluate(() => ({ name: window.nanopush.session.state.name, role: window.nanopush.session.state.role })), { name: 'alice', role: 'operator' });
  assert.ok(!alice.url().includes('token'), alice.url());
});
