// The alarm journal: every transition and every operator action, newest first, filtered by time
// range, alarm, transition or action, user and text, a page at a time, and exported as CSV (a
// download of /api/alarms/journal.csv with the same filters). Read through the alarms.journal
// command; while it shows the latest rows it refreshes itself when alarms change.

import { el, clear, setText } from '../dom.js';
import { call } from '../commands.js';
import { alarmFeed } from '../alarm_feed.js';
import { priorityBadge, formatStamp } from '../alarm_view.js';
import { runtimeNow } from '../runtime_clock.js';

const PAGE = 200;
const RANGES = [['1h', 'Last hour', 3600], ['8h', 'Last 8 h', 28800], ['1d', 'Last day', 86400], ['7d', 'Last 7 days', 604800],
  ['all', 'Everything', null], ['custom', 'From … to …', null]];
const ACTIONS = ['acknowledged', 'shelved', 'unshelved', 'commented', 'removed_from_service', 'returned_to_service'];
const PROCESS = ['activated', 'realarmed', 'level_changed', 'cleared', 'shelving_expired', 'suppressed', 'unsuppressed'];
const TRANSITION_TEXT = {
  activated: 'activated', realarmed: 're-alarmed', level_changed: 'level changed', cleared: 'cleared', acknowledged: 'acknowledged',
  shelved: 'shelved', unshelved: 'unshelved', shelving_expired: 'shelving expired', suppressed: 'suppressed', unsuppressed: 'unsuppressed',
  removed_from_service: 'out of service', returned_to_service: 'back in service', commented: 'commented',
};

function localInput(seconds) {
  const date = new Date(seconds * 1000);
  const pad = (n) => String(n).padStart(2, '0');
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())}T${pad(date.getHours())}:${pad(date.getMinutes())}`;
}

export async function mount(root, ctx) {
  const range = el('select', { id: 'journal-range', 'aria-label': 'Time range' }, ...RANGES.map(([key, label]) => el('option', { value: key, text: label })));
  range.value = ctx.params.range && RANGES.some(([key]) => key === ctx.params.range) ? ctx.params.range : '1d';
  const from = el('input', { type: 'datetime-local', id: 'journal-from', 'aria-label': 'From', hidden: true });
  const to = el('input', { type: 'datetime-local', id: 'journal-to', 'aria-label': 'To', hidden: true });
  const alarm = el('input', { type: 'search', id: 'journal-alarm', placeholder: 'Alarm (name or t01_*)', 'aria-label': 'Alarm', value: ctx.params.alarm || '' });
  const transition = el('select', { id: 'journal-transition', 'aria-label': 'Transition or action' },
    el('option', { value: '', text: 'All transitions and actions' }),
    el('option', { value: 'actions', text: 'Operator actions only' }),
    el('option', { value: 'process', text: 'Process transitions only' }),
    ...[...PROCESS, ...ACTIONS].map((name) => el('option', { value: name, text: TRANSITION_TEXT[name] })));
  const user = el('input', { type: 'search', id: 'journal-user', placeholder: 'User', 'aria-label': 'User', value: ctx.params.user || '' });
  const text = el('input', { type: 'search', id: 'journal-text', placeholder: 'Text in message or comment', 'aria-label': 'Text' });
  const exportLink = el('a', { class: 'btn secondary', id: 'journal-export', download: '', text: 'Export CSV' });
  const count = el('span', { class: 'count', role: 'status' });
  const newer = el('button', { type: 'button', class: 'btn small secondary', text: '← Newer' });
  const older = el('button', { type: 'button', class: 'btn small secondary', text: 'Older →' });
  const problem = el('div', { role: 'alert' });
  const body = el('tbody');
  root.append(el('section', { class: 'panel journal-page' },
    el('div', { class: 'panel-head' }, el('h1', { text: 'Alarm journal' }), count),
    el('div', { class: 'toolbar' }, range, from, to, alarm, transition, user, text, exportLink),
    problem,
    el('div', { class: 'scroll-x' }, el('table', { class: 'data journal-table' },
      el('thead', {}, el('tr', {}, ...['Time', 'Alarm', 'What', 'State after', 'Priority', 'Message', 'Value', 'By', 'Comment'].map((label) => el('th', { text: label })))),
      body)),
    el('div', { class: 'toolbar pager' }, newer, older)));

  let offset = 0;
  let asked = 0;  // answers to older requests are dropped

  function filters() {
    const args = {};
    const choice = RANGES.find(([key]) => key === range.value);
    if (range.value === 'custom') {
      if (from.value) args.since = new Date(from.value).getTime() / 1000;
      if (to.value) args.until = new Date(to.value).getTime() / 1000;
    } else if (choice && choice[2]) {
      args.since = Math.floor(runtimeNow(ctx.session) - choice[2]);
    }
    const name = alarm.value.trim();
    if (name) args.alarm = /[*?]/.test(name) ? name : `*${name}*`;
    if (transition.value === 'actions') args.transition = ACTIONS;
    else if (transition.value === 'process') args.transition = PROCESS;
    else if (transition.value) args.transition = [transition.value];
    if (user.value.trim()) args.user = user.value.trim();
    if (text.value.trim()) args.text = text.value.trim();
    return args;
  }

  function exportHref(args) {
    const query = new URLSearchParams();
    for (const [key, value] of Object.entries(args)) query.set(key, Array.isArray(value) ? value.join(',') : String(value));
    return `/api/alarms/journal.csv?${query}`;
  }

  async function load() {
    const mine = ++asked;
    const args = filters();
    exportLink.href = exportHref(args);
    clear(problem);
    let rows;
    try {
      rows = await call('alarms.journal', { ...args, limit: PAGE + 1, offset });
    } catch (error) {
      if (mine !== asked) return;
      problem.append(el('div', { class: 'error-banner', text: `The journal cannot be read: ${error.message}` }));
      return;
    }
    if (mine !== asked) return;
    const more = rows.length > PAGE;
    rows = rows.slice(0, PAGE);
    const now = runtimeNow(ctx.session);
    clear(body);
    if (!rows.length) body.append(el('tr', {}, el('td', { colspan: 9, class: 'muted', text: offset ? 'No older rows.' : 'Nothing in the journal for these filters.' })));
    for (const row of rows) {
      const by = row.user ? `${row.user}${row.role ? ` (${row.role})` : ''}` : (ACTIONS.includes(row.transition) ? row.origin || 'unknown' : 'process');
      body.append(el('tr', { 'data-transition': row.transition, 'data-alarm': row.alarm, 'data-user': row.user },
        el('td', { class: 'nowrap jtime', text: formatStamp(row.time, now) }),
        el('td', {}, el('strong', { text: row.alarm })),
        el('td', { class: `jt jt-${ACTIONS.includes(row.transition) ? 'action' : 'process'}`, text: TRANSITION_TEXT[row.transition] || row.transition }),
        el('td', { class: 'labelled', 'data-label': 'now', text: row.state.replace(/_/g, ' ') }),
        el('td', {}, row.priority ? priorityBadge(row.priority) : ''),
        el('td', { class: 'jmsg', text: row.message }),
        el('td', { class: 'num labelled', 'data-label': 'value', text: row.value }),
        el('td', { class: 'juser labelled', 'data-label': 'by', title: row.origin, text: by }),
        el('td', { class: 'small jcomment', text: row.comment })));
    }
    setText(count, rows.length ? `rows ${offset + 1}–${offset + rows.length}${more ? ' (more)' : ''}` : '');
    newer.disabled = offset === 0;
    older.disabled = !more;
    root.dataset.rows = String(rows.length);
  }

  const reload = () => { offset = 0; load(); };
  range.addEventListener('change', () => {
    const custom = range.value === 'custom';
    from.hidden = !custom;
    to.hidden = !custom;
    if (custom && !from.value) {
      const now = runtimeNow(ctx.session);
      from.value = localInput(now - 3600);
      to.value = localInput(now + 60);
    }
    reload();
  });
  for (const input of [from, to, transition]) input.addEventListener('change', reload);
  let typing = null;
  for (const input of [alarm, user, text]) input.addEventListener('input', () => { clearTimeout(typing); typing = setTimeout(reload, 300); });
  newer.addEventListener('click', () => { offset = Math.max(0, offset - PAGE); load(); });
  older.addEventListener('click', () => { offset += PAGE; load(); });

  // Showing the newest rows: new transitions and actions appear by themselves.
  let refresh = null;
  const stop = alarmFeed(ctx.live).use((change) => {
    if (offset !== 0 || range.value === 'custom' || !change.transitions.length) return;
    clearTimeout(refresh);
    refresh = setTimeout(load, 300);
  });
  await load();
  root.dataset.ready = '1';
  return () => {
    stop();
    clearTimeout(refresh);
    clearTimeout(typing);
  };
}
