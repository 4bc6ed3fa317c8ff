// Forced: every forced tag — its forced value (live), the value it had before, since when and by
// whom. Engineers unforce (or unforce and restore) here, and force another tag.

import { el, clear, setText } from '../dom.js';
import { tagMeta, allTagMeta } from '../api.js';
import { formatWithUnit, formatTime } from '../format.js';
import { forcedMark, showForced, listForces, openForce, openUnforce } from '../ops/forcing.js';
import { isEngineer } from '../commands.js';

export async function mount(root, ctx) {
  const engineer = isEngineer(ctx.session);
  const summary = el('p', { class: 'muted', role: 'status' });
  const body = el('tbody');
  const table = el('table', { class: 'data forced-table live-content' },
    el('thead', {}, el('tr', {}, ...['Tag', 'Forced value', 'Before', 'Since', 'By', ''].map((text) => el('th', { text })))), body);
  const tools = el('div', { class: 'toolbar force-tools' });
  if (engineer) {
    const input = el('input', { type: 'search', list: 'force-tag-names', placeholder: 'Tag name…', 'aria-label': 'Tag to force', id: 'force-tag' });
    const names = el('datalist', { id: 'force-tag-names' });
    const message = el('span', { class: 'error-text small', role: 'alert' });
    const open = async () => {
      setText(message, '');
      const [meta] = await tagMeta([input.value.trim()]);
      if (!meta) { setText(message, `No tag '${input.value.trim()}'`); return; }
      if (await openForce(ctx, meta)) refresh();
    };
    input.addEventListener('keydown', (event) => { if (event.key === 'Enter') open(); });
    tools.append(input, names, el('button', { type: 'button', class: 'btn danger', text: 'Force…', 'data-force-new': '1', onclick: open }), message);
    allTagMeta().then((tags) => names.append(...tags.filter((tag) => !tag.name.startsWith('_sys.')).map((tag) => el('option', { value: tag.name }))));
  } else {
    tools.append(el('span', { class: 'muted small', text: `Forcing and unforcing need the engineer role (you are ${ctx.session.role || 'a visitor'}).` }));
  }
  root.append(el('section', { class: 'panel' },
    el('div', { class: 'panel-head' }, el('h1', { text: 'Forced tags' })),
    el('p', { class: 'small muted', text: 'A forced tag keeps its forced value: programs read it, and their writes and every client\'s writes do not reach it until an engineer unforces it. Forces end when the runtime stops.' }),
    tools, summary, el('div', { class: 'scroll-x' }, table)));

  const rows = new Map();  // tag → {value, mark}
  let metas = new Map();
  const paint = (names) => {
    for (const name of names) {
      const row = rows.get(name);
      const item = ctx.live.get(name);
      if (!row || !item) continue;
      setText(row.value, formatWithUnit(item.v, row.unit));
      showForced(row.mark, item.f);
    }
  };
  const watch = ctx.live.watch(['_sys.forced'], (names) => {
    if (names.includes('_sys.forced') || names.some((name) => rows.has(name) && !(ctx.live.get(name) || {}).f)) refresh();
    paint(names);
  });
  let busy = false;
  let again = false;
  async function refresh() {
    if (busy) { again = true; return; }
    busy = true;
    try {
      const forces = await listForces();
      metas = new Map((await tagMeta(forces.map((force) => force.tag))).map((meta) => [meta.name, meta]));
      draw(forces);
    } catch (error) {
      setText(summary, `The forces cannot be listed: ${error.message}`);
    } finally {
      busy = false;
      if (again) { again = false; refresh(); }
    }
  }
  const draw = (forces) => {
    clear(body);
    rows.clear();
    setText(summary, forces.length ? `${forces.length} tag${forces.length === 1 ? ' is' : 's are'} forced.` : 'Nothing is forced.');
    table.hidden = !forces.length;
    for (const force of forces) {
      const meta = metas.get(force.tag) || { name: force.tag, unit: '', type: '' };
      const unit = meta.unit || '';
      const value = el('span', { class: 'live-value num', text: formatWithUnit(force.value, unit) });
      const mark = forcedMark(true);
      const actions = el('td', {});
      if (engineer) {
        actions.append(el('button', { type: 'button', class: 'btn small secondary', text: 'Unforce…', 'data-unforce': force.tag,
          onclick: async () => { if (await openUnforce(ctx, meta, force)) refresh(); } }));
      }
      body.append(el('tr', { 'data-tag': force.tag },
        el('td', {}, el('strong', { text: force.tag }), meta.description ? el('span', { class: 'd', text: meta.description }) : null),
        el('td', { class: 'tnum' }, mark, ' ', value),
        el('td', { class: 'tnum', text: formatWithUnit(force.previous, unit) }),
        el('td', { class: 'tnum', text: formatTime(force.since) }),
        el('td', { class: 'by', text: force.by }),
        actions));
      rows.set(force.tag, { value, mark, unit });
    }
    watch.update(['_sys.forced', ...rows.keys()]);
    paint([...rows.keys()]);
    root.dataset.ready = '1';
  };
  await refresh();
  return () => watch.close();
}
