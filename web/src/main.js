// Boot: the operator page (src/app.js, with three and uPlot, bundled by `npm run build`) or the
// monitoring view (`?view=monitor`, src/monitor.js, no packages); each exports `start()`. A
// page whose modules cannot load (or start) says why (not built: `cd web && npm ci && npm run
// build`) instead of saying "starting" forever.
const view = new URLSearchParams(location.search).get('view');

function bootError(e) {
  const el = document.getElementById('boot-error');
  const txt = document.querySelector('#st-conn .txt');
  const msg = `The page could not start: ${e && e.message ? e.message : e}. ` +
    'If web/dist is missing or old, build the client on the server: cd web && npm ci && npm run build (or make web), then reload.';
  if (el) {
    el.textContent = msg;
    el.hidden = false;
  }
  if (txt) txt.textContent = 'not started';
  console.warn(msg);
}

// The token of the URL is exchanged for a session cookie first and removed from the address bar
// (src/connection.js, `exchangeToken`); the page then connects with the cookie. A page that
// exchanged none asks whether the server knows this person (its cookie): one that does not is
// told so on the page (the page still starts, and connects once it does). One request to
// /api/session either way.
function signInNote(text) {
  const el = document.getElementById('boot-error');
  if (!text || !el) return;
  el.textContent = text;
  el.hidden = false;
}

import('./connection.js')
  .then(async (c) => {
    const signedIn = await c.exchangeToken(location);
    if (!signedIn && !new URLSearchParams(location.search).has('demo')) signInNote(await c.signInNote());
  })
  .then(() => (view === 'monitor' ? import('./monitor.js') : import('./app.js')))
  .then((page) => page.start())
  .catch(bootError);
