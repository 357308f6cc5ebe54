// node --test: the records list's rows (src/records.js): newest first, outcomes of this page's pushes.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { recordRows, outcomeText, RECORDS_SHOWN, olderText } from '../src/records.js';
import { formatTime } from '../src/format.js';

test('rows newest first, scans openable, sizes in words, push outcomes', () => {
  const list = [
    { name: 'scan-1-1.gsf', kind: 'scan', bytes: 4200, modified: '2024-05-01T10:00:00Z' },
    { name: 'push-1-2.csv', kind: 'push', bytes: 300, modified: '2024-05-01T11:00:00Z' },
    { name: 'push-1-3.csv', bytes: 2 * 1024 * 1024, modified: '2024-05-01T12:00:00Z' },
  ];
  const outcomes = new Map([
    ['push-1-2.csv', { outcome: 'ok' }],
    ['push-1-3.csv', { outcome: 'stopped', failure: 'stop requested by the operator' }],
  ]);
  const rows = recordRows(list, outcomes);
  assert.deepEqual(rows.map((r) => r.name), ['push-1-3.csv', 'push-1-2.csv', 'scan-1-1.gsf']);
  assert.deepEqual(rows[0], {
    name: 'push-1-3.csv', kind: '', outcome: 'stopped: stop requested by the operator', size: '2.0 MiB',
    modified: formatTime('2024-05-01T12:00:00Z'), openable: false,
  });
  assert.deepEqual([rows[1].outcome, rows[1].size, rows[1].openable], ['ok', '300 B', false]);
  assert.deepEqual([rows[2].outcome, rows[2].size, rows[2].openable, rows[2].kind], ['', '4.1 KiB', true, 'scan']);
  assert.equal(list[0].name, 'scan-1-1.gsf', 'the list itself is not reordered');
  assert.deepEqual(recordRows([]), []);
});

test('outcomes in words', () => {
  assert.equal(outcomeText(undefined), '');
  assert.equal(outcomeText({ outcome: 'ok', failure: null }), 'ok');
  assert.equal(outcomeText({ outcome: 'plan', failure: null }), 'plan: ');
});

test('thousands of records: the newest few hundred, and how many more', () => {
  // 10 000 rows hold the page for 3.5 s each time the list is refreshed (after every push).
  const list = Array.from({ length: 10000 }, (_, i) => ({ name: `push-${1700000000 + i}-r${i}-p1.csv`, kind: 'push', bytes: 10, modified: 1700000000 + i }));
  const rows = recordRows(list);
  assert.equal(rows.length, RECORDS_SHOWN);
  assert.ok(RECORDS_SHOWN <= 300, `${RECORDS_SHOWN} rows shown`);
  assert.equal(rows[0].name, 'push-1700009999-r9999-p1.csv', 'newest first');
  assert.equal(olderText(list.length), `and ${10000 - RECORDS_SHOWN} older records in the data directory (GET /api/records?offset=${RECORDS_SHOWN} lists them, a page at a time)`);
  assert.equal(olderText(RECORDS_SHOWN), null);
});
