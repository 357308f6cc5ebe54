// Boot: the operator page (src/app.js, which needs three and uPlot from node_modules) or the
// monitoring view (`?view=monitor`, src/monitor.js, no packages); each exports `start()`. A
// page whose modules cannot load (or start) says why (the packages are missing: `cd web && npm
// ci`) instead of saying "starting" forever.
const view = new URLSearchParams(location.search).get('view');

function bootError(e) {
  const el = document.getElementById('boot-error');
  const txt = document.querySelector('#st-conn .txt');
  const msg = `The page could not start: ${e && e.message ? e.message : e}. ` +
    'If web/node_modules is missing, install the client\'s packages on the server: cd web && npm ci (or make web), then reload.';
  if (el) {
    el.textContent = msg;
    el.hidden = false;
  }
  if (txt) txt.textContent = 'not started';
  console.warn(msg);
}

(view === 'monitor' ? import('./monitor.js') : import('./app.js')).then((page) => page.start()).catch(bootError);
