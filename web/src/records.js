// The records list (`/api/records`): newest first, each a download link, the scans (`.gsf`) with
// an Open button that shows them in the views, and the outcome of the push that wrote a record
// (from the `run_done` events this page saw). `recordRows` is pure (Node tests).
import { apiUrl } from './connection.js';
import { formatBytes, formatTime } from './format.js';

/** What a `run_done` says in the Outcome column. */
export function outcomeText(run) {
  if (!run) return '';
  return run.outcome === 'ok' ? 'ok' : `${run.outcome}: ${run.failure ?? ''}`;
}

/**
 * Rows the table shows at most: a data directory grows by four files a push and a scan, and ten
 * thousand rows hold the page (Stop included) for 3.5 s each time the list is refreshed.
 */
export const RECORDS_SHOWN = 200;

/** The note under the table when `total` records are more than it shows, else null. */
export function olderText(total) {
  return total > RECORDS_SHOWN ? `and ${total - RECORDS_SHOWN} older records in the data directory (GET /api/records?offset=${RECORDS_SHOWN} lists them, a page at a time)` : null;
}

/**
 * The table's rows for an /api/records list, the newest `RECORDS_SHOWN`, newest first: {name,
 * kind, outcome, size, modified, openable}; `outcomes` maps a record name to the `run_done` that
 * wrote it.
 */
export function recordRows(list, outcomes = new Map()) {
  return [...list]
    .sort((a, b) => String(b.modified).localeCompare(String(a.modified)))
    .slice(0, RECORDS_SHOWN)
    .map((rec) => ({
      name: rec.name,
      kind: rec.kind ?? '',
      outcome: outcomeText(outcomes.get(rec.name)),
      size: formatBytes(rec.bytes),
      modified: formatTime(rec.modified),
      openable: rec.name.endsWith('.gsf'),
    }));
}

/** A row of one cell across the table, saying `text`. */
function note(text, span = 5) {
  const tr = document.createElement('tr');
  const td = document.createElement('td');
  td.colSpan = span;
  td.textContent = text;
  tr.append(td);
  return tr;
}

export class Records {
  /**
   * @param {HTMLElement} body the table's `<tbody>`
   * @param {{loc: Location, demo?: boolean, onOpen: (name: string) => void}} opts `onOpen`:
   *   show the scan record `name` in the views
   */
  constructor(body, { loc, demo = false, onOpen }) {
    this.body = body;
    this.loc = loc;
    this.demo = demo;
    this.onOpen = onOpen;
    this.outcomes = new Map(); // record name → run_done
  }

  /** A finished push: its record's outcome. */
  noteRun(run) {
    if (run.record) this.outcomes.set(run.record, run);
  }

  /** Lists the records again. */
  async refresh() {
    const body = this.body;
    if (this.demo) {
      body.replaceChildren(note('(demo: no records)'));
      return;
    }
    try {
      // One page, the newest: the server says how many there are in all.
      const r = await fetch(apiUrl(`/api/records?limit=${RECORDS_SHOWN}`, this.loc));
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      const list = await r.json();
      const total = Number(r.headers.get('X-Total-Count') ?? list.length);
      if (!list.length) {
        body.replaceChildren(note('no records yet'));
        return;
      }
      const rows = recordRows(list, this.outcomes).map((rec) => this.row(rec));
      const older = olderText(Math.max(total, list.length));
      body.replaceChildren(...rows, ...(older ? [note(older)] : []));
    } catch (e) {
      body.replaceChildren(note(`could not list records: ${e.message}`));
    }
  }

  row(rec) {
    const tr = document.createElement('tr');
    const a = document.createElement('a');
    a.href = apiUrl(`/api/records/${encodeURIComponent(rec.name)}`, this.loc);
    a.download = rec.name;
    a.textContent = rec.name;
    const first = document.createElement('span');
    first.append(a);
    if (rec.openable) {
      const b = document.createElement('button');
      b.type = 'button';
      b.className = 'small';
      b.textContent = 'Open';
      b.setAttribute('aria-label', `Open ${rec.name} in the views`);
      b.addEventListener('click', () => this.onOpen(rec.name));
      first.append(' ', b);
    }
    for (const c of [first, rec.kind, rec.outcome, rec.size, rec.modified]) {
      const td = document.createElement('td');
      td.append(c);
      tr.append(td);
    }
    return tr;
  }
}
