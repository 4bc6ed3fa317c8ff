// Audit: the audit trail of every client write and every action (engineers; audit.query), with
// filters (time, tag or command, user, source, refused only) and a CSV export of what matches.

import { el, clear, setText } from '../dom.js';
import { formatValue } from '../format.js';
import { command } from '../commands.js';

const PAGE = 200;  // rows asked for at a time ("More" asks for the next ones)
const SOURCES = ['hmi', 'opcua', 'modbus', 'cli'];

function field(label, input) {
  return el('label', { class: 'filter' }, el('span', { text: label }), input);
}

function pad(n, width = 2) { return String(n).padStart(width, '0'); }

/** Local date and time with milliseconds: 2026-11-24 12:12:34.712 */
function stamp(seconds) {
  const date = new Date(seconds * 1000);
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())} ${pad(date.getHours())}:${pad(date.getMinutes())}:${pad(date.getSeconds())}.${pad(date.getMilliseconds(), 3)}`;
}

/** A value as recorded, exactly (no rounding: the trail is evidence). */
function exact(value) {
  if (value === null || value === undefined) return '';
  if (typeof value === 'number') return String(value);
  return typeof value === 'object' ? JSON.stringify(value) : formatValue(value);
}

function what(row) {
  if (row.kind === 'write') return row.name;
  const args = row.arguments && typeof row.arguments === 'object' ? row.arguments : {};
  const shown = row.tag ? [row.tag] : [];
  for (const [key, value] of Object.entries(args)) if (!row.tag || (key !== 'tag' && key !== 'value')) shown.push(`${key}=${exact(value)}`);
  return [row.name, ...shown].join(' ');
}

function result(row) {
  if (row.accepted) return row.kind === 'command' && row.detail ? `accepted: ${row.detail}` : 'accepted';
  const rule = row.rule === 'refused' ? '' : `${row.rule}: `;
  return row.detail ? `refused: ${rule}${row.detail}` : `refused: ${row.rule}`;
}

export async function mount(root, ctx) {
  const since = el('input', { type: 'datetime-local', step: 1, 'aria-label': 'From', name: 'since' });
  const until = el('input', { type: 'datetime-local', step: 1, 'aria-label': 'To', name: 'until' });
  const subject = el('input', { type: 'search', placeholder: 't01_* or tags.*', name: 'subject', 'aria-label': 'Tag or command' });
  const user = el('input', { type: 'search', placeholder: 'user', name: 'user', 'aria-label': 'User' });
  const source = el('select', { name: 'source', 'aria-label': 'Source' }, el('option', { value: '', text: 'any source' }),
    ...SOURCES.map((name) => el('option', { value: name, text: name })));
  const refused = el('input', { type: 'checkbox', name: 'refused' });
  const search = el('button', { type: 'submit', class: 'btn', text: 'Show' });
  const exportLink = el('a', { class: 'btn secondary', href: '/api/audit.csv', download: '', text: 'Export CSV', 'data-export': 'csv' });
  const form = el('form', { class: 'audit-filters', role: 'search' },
    field('From', since), field('To', until), field('Tag or command', subject), field('User', user), field('Source', source),
    el('label', { class: 'filter check' }, refused, el('span', { text: 'refused only' })),
    el('div', { class: 'filter-actions' }, search, exportLink));
  const status = el('p', { class: 'muted small', role: 'status' });
  const body = el('tbody');
  const table = el('table', { class: 'data audit-table' },
    el('thead', {}, el('tr', {}, ...['Time', 'Source', 'User', 'Peer', 'Tag / command', 'Old', 'New', 'Result'].map((text) => el('th', { text, class: text === 'Old' || text === 'New' ? 'num' : null })))), body);
  const more = el('button', { type: 'button', class: 'btn secondary', text: 'More', hidden: true });
  root.append(el('section', { class: 'panel' },
    el('div', { class: 'panel-head' }, el('h1', { text: 'Audit trail' }),
      el('span', { class: 'muted small', text: 'every client write and every action, accepted or refused (docs/operations.md)' })),
    form, status, el('div', { class: 'scroll-x' }, table), more));

  // The filters as audit.query's arguments. A text with * or ? is a pattern; "tags.*" is a command.
  const filters = () => {
    const args = {};
    const seconds = (input) => (input.value ? new Date(input.value).getTime() / 1000 : null);
    if (seconds(since) !== null) args.since = seconds(since);
    if (seconds(until) !== null) args.until = seconds(until);
    const text = subject.value.trim();
    if (text) {
      if (/^[a-z_]+\.[a-z_*?]+$/i.test(text) && !text.startsWith('_sys.')) args.command = text;
      else args.tag = text;
    }
    if (user.value.trim()) args.user = user.value.trim();
    if (source.value) args.source = source.value;
    if (refused.checked) args.result = 'refused';
    return args;
  };
  const exportHref = (args) => {
    const query = new URLSearchParams(Object.entries(args).map(([key, value]) => [key, String(value)]));
    return `/api/audit.csv${query.toString() ? `?${query}` : ''}`;
  };

  let offset = 0;
  let current = {};
  const load = async (append) => {
    if (!append) { offset = 0; current = filters(); clear(body); }
    exportLink.setAttribute('href', exportHref(current));
    search.disabled = true;
    setText(status, 'Reading the audit trail…');
    const answer = await command('audit.query', { ...current, limit: PAGE, offset });
    search.disabled = false;
    if (!answer.ok) {
      setText(status, answer.status === 404 ? 'This runtime keeps no audit trail (audit: enabled: false, or --no-audit).' : `The audit trail cannot be read: ${answer.error}`);
      status.className = 'error-text small';
      more.hidden = true;
      root.dataset.ready = '1';
      return;
    }
    status.className = 'muted small';
    for (const row of answer.result) {
      body.append(el('tr', { class: row.accepted ? '' : 'refused', 'data-kind': row.kind, 'data-name': row.name },
        el('td', { class: 'num nowrap', text: stamp(row.time), title: row.time_utc }),
        el('td', { text: row.source }),
        el('td', { text: row.user || (row.source === 'modbus' ? '—' : '') }),
        el('td', { class: 'small', text: row.peer }),
        el('td', { class: 'what', text: what(row) }),
        el('td', { class: 'num', text: exact(row.old) }),
        el('td', { class: 'num', text: exact(row.new) }),
        el('td', { class: row.accepted ? 'ok-text' : 'error-text', text: result(row) })));
    }
    offset += answer.result.length;
    more.hidden = answer.result.length < PAGE;
    setText(status, offset ? `${offset} entr${offset === 1 ? 'y' : 'ies'}${more.hidden ? '' : ' so far'}, newest first.` : 'No audit entries match.');
    root.dataset.ready = '1';
  };
  form.addEventListener('submit', (event) => { event.preventDefault(); load(false); });
  more.addEventListener('click', () => load(true));
  await load(false);
  return () => {};
}
