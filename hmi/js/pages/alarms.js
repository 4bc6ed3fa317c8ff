// The alarm summary: every alarm that is not normal, live, sortable by priority or time, with
// its ISA-18.2 state in words and marks, the message, the watched tag's live value and since
// when; acknowledge, acknowledge all, shelve (timed or one-shot, with a reason), unshelve and
// comment for the roles the runtime allows (the buttons follow GET /api/commands; the server
// refuses a forged request anyway). Actions go through the commands door (commands.js).

import { el, clear, setText } from '../dom.js';
import { tagMeta } from '../api.js';
import { call, allowedCommands } from '../commands.js';
import { alarmFeed } from '../alarm_feed.js';
import { openActionDialog } from '../action_dialog.js';
import { priorityBadge, priorityRank, stateChip, needsAcknowledgement, formatStamp, formatAge } from '../alarm_view.js';
import { formatWithUnit, qualityClass } from '../format.js';
import { runtimeNow } from '../runtime_clock.js';

const VIEWS = {
  annunciated: { label: 'Annunciated', states: ['unacknowledged', 'acknowledged', 'returned', 'latched'] },
  shelved: { label: 'Shelved', states: ['shelved'] },
  hidden: { label: 'Suppressed, out of service', states: ['suppressed', 'out_of_service'] },
  all: { label: 'All not normal', states: null },
};
const SHELVE_CHOICES = [['10 min', 600], ['30 min', 1800], ['1 h', 3600], ['2 h', 7200], ['4 h', 14400], ['8 h', 28800]];
const MAX_ROWS = 500;

export async function mount(root, ctx) {
  const feed = alarmFeed(ctx.live);
  const allowed = await allowedCommands(ctx.session);
  const may = (name) => allowed.get(name) === true;
  const view = el('select', { 'aria-label': 'Which alarms', id: 'alarm-view' },
    ...Object.entries(VIEWS).map(([key, { label }]) => el('option', { value: key, text: label })));
  view.value = VIEWS[ctx.params.show] ? ctx.params.show : 'annunciated';
  const sort = el('select', { 'aria-label': 'Sort by', id: 'alarm-sort' },
    el('option', { value: 'priority', text: 'Sort: priority, then newest' }), el('option', { value: 'time', text: 'Sort: newest first' }));
  sort.value = ctx.params.sort === 'time' ? 'time' : 'priority';
  const counts = el('span', { class: 'count', role: 'status' });
  const status = el('div', { class: 'action-status', role: 'status', 'aria-live': 'polite' });
  const ackAll = may('alarms.acknowledge_all')
    ? el('button', { type: 'button', class: 'btn', 'data-action': 'acknowledge_all', text: 'Acknowledge all' })
    : null;
  const note = ackAll ? null : el('span', { class: 'muted small', text: `Acknowledging and shelving need the operator or engineer role (you are ${ctx.session.role}).` });
  const sortHeader = (key, label) => el('th', { 'data-sort': key },
    el('button', { type: 'button', class: 'th-sort', text: label, onclick: () => { sort.value = key; render(); } }));
  const head = el('tr', {}, sortHeader('priority', 'Priority'), el('th', { text: 'State' }), el('th', { text: 'Alarm' }),
    el('th', { class: 'num', text: 'Value' }), sortHeader('time', 'Since'), el('th', { text: 'Comment' }), el('th', { text: '' }));
  const body = el('tbody');
  root.append(
    el('section', { class: 'panel alarms-page' },
      el('div', { class: 'panel-head' }, el('h1', { text: 'Alarms' }), counts),
      el('div', { class: 'toolbar' }, view, sort, ackAll, note),
      status,
      el('div', { class: 'scroll-x' }, el('table', { class: 'data alarm-table live-content' }, el('thead', {}, head), body))),
  );

  const units = new Map();  // tag → unit
  const values = new Map();  // tag → [value cells]
  const watch = ctx.live.watch([], (names) => paintValues(names));

  const say = (text, ok) => {
    clear(status);
    status.append(el('div', { class: ok ? 'done' : 'refusal', text }));
  };
  const act = async (name, args, label) => {
    try {
      say(await call(name, args) || `${label}: done`, true);
    } catch (error) {
      say(`${label} refused — ${error.message}`, false);
    }
  };

  function shelveDialog(alarm) {
    const longest = (feed.summary && feed.summary.shelve_max) || 28800;
    const choices = SHELVE_CHOICES.filter(([, seconds]) => seconds <= longest);
    return openActionDialog({
      title: `Shelve ${alarm.name}`,
      intro: `${alarm.message}. A shelved alarm is not annunciated; it comes back by itself when the shelving ends.`,
      submitLabel: 'Shelve',
      build: () => {
        const reason = el('input', { type: 'text', id: 'shelve-reason', autocomplete: 'off', maxlength: 500 });
        const timed = el('input', { type: 'radio', name: 'kind', value: 'timed', checked: true });
        const oneShot = el('input', { type: 'radio', name: 'kind', value: 'one_shot' });
        const duration = el('select', { id: 'shelve-duration' }, ...choices.map(([label, seconds]) => el('option', { value: String(seconds), text: label })),
          el('option', { value: 'custom', text: 'Other…' }));
        const custom = el('input', { type: 'text', id: 'shelve-custom', placeholder: 'e.g. 45min, 90s', hidden: true, autocomplete: 'off' });
        duration.addEventListener('change', () => { custom.hidden = duration.value !== 'custom'; });
        return {
          body: [
            el('label', { for: 'shelve-reason', text: 'Reason (required)' }), reason,
            el('div', { class: 'choices', role: 'radiogroup', 'aria-label': 'How long' },
              el('label', {}, timed, 'For a time'), el('label', {}, oneShot, 'One-shot: until it clears')),
            el('label', { for: 'shelve-duration', text: `Duration (at most ${formatAge(longest)})` }), duration, custom,
          ],
          read: () => {
            if (!reason.value.trim()) return 'Give a reason: shelving is recorded with it.';
            const args = { alarm: alarm.name, reason: reason.value.trim() };
            if (oneShot.checked) return { ...args, one_shot: true };
            if (duration.value === 'custom') return custom.value.trim() ? { ...args, duration: custom.value.trim() } : 'Give a duration, e.g. 45min.';
            return { ...args, duration: Number(duration.value) };
          },
        };
      },
      submit: (args) => call('alarms.shelve', args),
    });
  }

  function textDialog(alarm, { command, title, label, submitLabel, required, key }) {
    return openActionDialog({
      title: `${title} ${alarm.name}`,
      intro: alarm.message,
      submitLabel,
      build: () => {
        const text = el('textarea', { id: 'action-text', rows: 3, maxlength: 1000 });
        return {
          body: [el('label', { for: 'action-text', text: label }), text],
          read: () => (required && !text.value.trim() ? `${label.replace(/ \(.*\)$/, '')}: please write something.` : { alarm: alarm.name, [key]: text.value.trim() }),
        };
      },
      submit: (args) => call(command, args),
    });
  }

  function actions(alarm) {
    const cell = el('td', { class: 'actions-cell' });
    const button = (action, text, onclick, primary) => el('button', { type: 'button', class: `btn small ${primary ? '' : 'secondary'}`, 'data-action': action, text, onclick });
    if (needsAcknowledgement(alarm) && may('alarms.acknowledge')) {
      cell.append(button('acknowledge', 'Acknowledge', () => act('alarms.acknowledge', { alarm: alarm.name }, `Acknowledge ${alarm.name}`), true));
    }
    if (alarm.state === 'shelved' && may('alarms.unshelve')) {
      cell.append(button('unshelve', 'Unshelve…', () => textDialog(alarm, { command: 'alarms.unshelve', title: 'Unshelve', label: 'Reason (optional)', submitLabel: 'Unshelve', key: 'reason' })));
    } else if (alarm.state !== 'out_of_service' && alarm.state !== 'shelved' && may('alarms.shelve')) {
      cell.append(button('shelve', 'Shelve…', () => shelveDialog(alarm)));
    }
    if (may('alarms.comment')) {
      cell.append(button('comment', 'Comment…', () => textDialog(alarm, { command: 'alarms.comment', title: 'Comment on', label: 'Comment', submitLabel: 'Add comment', required: true, key: 'comment' })));
    }
    return cell;
  }

  function chosen() {
    const states = VIEWS[view.value].states;
    const rows = feed.list().filter((alarm) => !states || states.includes(alarm.state));
    if (sort.value === 'time') rows.sort((a, b) => b.since - a.since);
    else rows.sort((a, b) => priorityRank(b.priority) - priorityRank(a.priority) || b.severity - a.severity || b.since - a.since);
    return rows;
  }

  async function render() {
    const now = runtimeNow(ctx.session);
    const rows = chosen();
    for (const th of head.querySelectorAll('th[data-sort]')) th.setAttribute('aria-sort', th.dataset.sort === sort.value ? 'descending' : 'none');
    const summary = feed.summary;
    setText(counts, summary ? `${summary.active} active · ${summary.unacknowledged} unacknowledged · ${summary.shelved} shelved` : '');
    if (ackAll) {
      const waiting = summary ? summary.unacknowledged : 0;
      ackAll.disabled = !waiting;
      setText(ackAll, `Acknowledge all (${waiting})`);
    }
    clear(body);
    values.clear();
    if (!feed.synced) {
      body.append(el('tr', {}, el('td', { colspan: 7, class: 'muted', text: ctx.live.state === 'live' ? 'Loading alarms…' : 'Not connected: the alarm state is unknown.' })));
      return;
    }
    if (!rows.length) {
      body.append(el('tr', { class: 'empty' }, el('td', { colspan: 7, class: 'muted', text: view.value === 'annunciated' ? 'No alarms: the plant is normal.' : 'None.' })));
    }
    for (const alarm of rows.slice(0, MAX_ROWS)) {
      const value = el('span', { class: 'live-value num' });
      if (!values.has(alarm.tag)) values.set(alarm.tag, []);
      values.get(alarm.tag).push(value);
      const comment = alarm.comment ? `${alarm.comment}${alarm.comment_user ? ` — ${alarm.comment_user}` : ''}` : '';
      const shelvedBy = alarm.state === 'shelved' && alarm.shelving ? `shelved${alarm.shelving.user ? ` by ${alarm.shelving.user}` : ''}: ${alarm.shelving.reason}` : '';
      body.append(el('tr', { 'data-alarm': alarm.name, 'data-state': alarm.state, class: `arow astate-row-${alarm.state}` },
        el('td', { 'data-label': 'Priority' }, priorityBadge(alarm.priority, alarm.active)),
        el('td', { 'data-label': 'State' }, stateChip(alarm, now)),
        el('td', { class: 'alarm-what' }, el('strong', { class: 'alarm-name', text: alarm.name }), el('span', { class: 'alarm-message', text: alarm.message }),
          alarm.description ? el('span', { class: 'alarm-desc', text: alarm.description }) : null),
        el('td', { class: 'num', 'data-label': 'Value' }, el('button', { type: 'button', class: 'linklike', title: `${alarm.tag}: details and trend`, onclick: () => openTag(alarm.tag) }, value)),
        el('td', { 'data-label': 'Since' }, el('span', { class: 'since', 'data-since': alarm.since, text: formatStamp(alarm.since, now) }),
          el('span', { class: 'age muted small', 'data-since': alarm.since, text: ` (${formatAge(now - alarm.since)})` })),
        el('td', { class: 'comment small', 'data-label': 'Comment', text: [comment, shelvedBy].filter(Boolean).join(' · ') }),
        actions(alarm)));
    }
    if (rows.length > MAX_ROWS) body.append(el('tr', {}, el('td', { colspan: 7, class: 'muted', text: `${rows.length - MAX_ROWS} more not shown: choose a narrower view.` })));
    const tags = [...values.keys()];
    const missing = tags.filter((tag) => !units.has(tag));
    if (missing.length) {
      for (const meta of await tagMeta(missing)) units.set(meta.name, meta);
    }
    watch.update(tags);
    paintValues(tags);
  }

  function paintValues(names) {
    for (const name of names) {
      const item = ctx.live.get(name);
      const meta = units.get(name);
      for (const cell of values.get(name) || []) {
        setText(cell, item ? formatWithUnit(item.v, meta ? meta.unit : '') : '—');
        cell.className = `live-value num ${item ? qualityClass(item.q) : ''}`;
      }
    }
  }

  async function openTag(tag) {
    const { openTagDetails } = await import('../tag_details.js');
    const [meta] = await tagMeta([tag]);
    if (meta) openTagDetails(ctx, meta);
  }

  if (ackAll) {
    ackAll.addEventListener('click', () => openActionDialog({
      title: 'Acknowledge all alarms',
      intro: `Acknowledge the ${feed.summary ? feed.summary.unacknowledged : ''} alarm(s) waiting for it, as ${ctx.session.user}?`,
      submitLabel: 'Acknowledge all',
      build: () => {
        const text = el('input', { type: 'text', id: 'action-text', autocomplete: 'off', maxlength: 500 });
        return { body: [el('label', { for: 'action-text', text: 'Comment (optional)' }), text], read: () => ({ comment: text.value.trim() }) };
      },
      submit: (args) => call('alarms.acknowledge_all', args),
    }));
  }
  view.addEventListener('change', render);
  sort.addEventListener('change', render);
  let rendering = null;
  const stop = feed.use(() => {
    // Many changes in a row: one render per frame.
    if (!rendering) rendering = requestAnimationFrame(() => { rendering = null; render(); });
  });
  const ages = setInterval(() => {
    const now = runtimeNow(ctx.session);
    for (const age of body.querySelectorAll('.age')) setText(age, ` (${formatAge(now - Number(age.dataset.since))})`);
  }, 1000);
  await render();
  root.dataset.ready = '1';
  return () => {
    stop();
    watch.close();
    clearInterval(ages);
    if (rendering) cancelAnimationFrame(rendering);
  };
}
