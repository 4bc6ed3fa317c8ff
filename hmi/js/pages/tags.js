// Tags: every tag with its live value, quality, timestamp, unit, range, access and description.
// Made for 10,000 tags: only the rows in view exist in the page (a pool of row elements moved
// as you scroll), and only their tags are subscribed on the live channel.

import { el, clear, setText } from '../dom.js';
import { allTagMeta } from '../api.js';
import { formatValue, formatTime, formatRange, qualityName, qualityClass } from '../format.js';
import { forcedMark, showForced } from '../ops/forcing.js';

const OVERSCAN = 8;

export async function mount(root, ctx) {
  const canWrite = ctx.session.role && ctx.session.role !== 'viewer';
  const search = el('input', { type: 'search', placeholder: 'Search tag names…', 'aria-label': 'Search tag names', value: ctx.params.q || '' });
  const group = el('select', { 'aria-label': 'Group' }, el('option', { value: '', text: 'All groups' }));
  const count = el('span', { class: 'count', role: 'status' });
  const head = el('div', { class: 'vrow vhead', role: 'row' },
    el('span', { text: 'Tag' }), el('span', { text: 'Value' }), el('span', { class: 'qcol', text: 'Quality' }),
    el('span', { class: 'ts', text: 'Time' }), el('span', { class: 'range', text: 'Range' }), el('span', { class: 'acc', text: 'Access' }), el('span', { text: '' }));
  const spacer = el('div', { class: 'vspacer' });
  const body = el('div', { class: 'vbody live-content', tabindex: 0, role: 'rowgroup' }, spacer);
  root.append(el('div', { class: 'tags-page' },
    el('div', { class: 'toolbar' }, search, group, count),
    el('div', { class: 'vtable', role: 'table', 'aria-label': 'Tags' }, head, body)));

  const all = await allTagMeta();
  const groups = [...new Set(all.map((tag) => tag.group || '(no group)'))];
  for (const name of groups) group.append(el('option', { value: name, text: name }));
  if (ctx.params.group) group.value = ctx.params.group;

  const openTag = async (tag) => (await import('../tag_details.js')).openTagDetails(ctx, tag);
  let rows = all;
  const pool = [];
  let rowHeight = 44;
  const watch = ctx.live.watch([], () => paintValues());
  let visible = [];

  const makeRow = () => {
    const name = el('span', { class: 'n', role: 'button', tabindex: 0, title: 'details' });
    const forced = forcedMark(false);
    const description = el('span', { class: 'd' });
    const value = el('span', { class: 'live-value' });
    const unit = el('span', { class: 'u' });
    const quality = el('span', { class: 'qual' });
    const time = el('span', { class: 'ts num' });
    const range = el('span', { class: 'range num' });
    const access = el('span', { class: 'acc' });
    const action = el('span');
    // The name opens the tag's details (with its trend when it is historized).
    const nameCell = el('span', { class: 'name', role: 'button', tabindex: 0, title: 'Details and trend',
      onclick: () => row.tag && openTag(row.tag), onkeydown: (event) => { if (event.key === 'Enter' && row.tag) openTag(row.tag); } }, name, description);
    const node = el('div', { class: 'vrow', role: 'row' },
      nameCell, el('span', { class: 'val' }, forced, value, unit),
      el('span', { class: 'qcol' }, quality), time, range, access, action);
    const row = { node, name, description, value, unit, quality, time, range, access, action, forced, tag: null };
    body.append(node);
    return row;
  };

  const render = () => {
    rowHeight = parseFloat(getComputedStyle(document.documentElement).getPropertyValue('--row')) || 44;
    spacer.style.height = `${rows.length * rowHeight}px`;
    const first = Math.max(0, Math.floor(body.scrollTop / rowHeight) - OVERSCAN);
    const last = Math.min(rows.length, Math.ceil((body.scrollTop + body.clientHeight) / rowHeight) + OVERSCAN);
    while (pool.length < last - first) pool.push(makeRow());
    visible = [];
    pool.forEach((row, index) => {
      const tag = rows[first + index];
      if (!tag || first + index >= last) { row.node.hidden = true; row.tag = null; return; }
      row.node.hidden = false;
      row.node.style.transform = `translateY(${(first + index) * rowHeight}px)`;
      if (row.tag !== tag) {
        row.tag = tag;
        row.node.dataset.tag = tag.name;
        setText(row.name, tag.name);
        row.name.title = tag.name;
        setText(row.description, tag.description || '');
        row.description.title = tag.description || '';
        setText(row.unit, tag.unit || '');
        setText(row.range, formatRange(tag));
        setText(row.access, tag.access);
        clear(row.action);
        if (canWrite && tag.writable) {
          row.action.append(el('button', { type: 'button', class: 'btn small secondary', text: 'Write…', 'data-write': tag.name,
            onclick: () => ctx.openWrite(tag) }));
        }
      }
      visible.push(row);
    });
    setText(count, `${rows.length.toLocaleString()} of ${all.length.toLocaleString()} tags`);
    paintValues();
    subscribeSoon();
  };

  let subscribeTimer = null;
  const subscribeSoon = () => {
    clearTimeout(subscribeTimer);
    // While scrolling fast, wait until the rows settle before asking for their values.
    subscribeTimer = setTimeout(() => watch.update(visible.map((row) => row.tag.name)), 60);
  };

  function paintValues() {
    for (const row of visible) {
      const item = ctx.live.get(row.tag.name);
      const value = item ? item.v : row.tag.value;
      const quality = item ? item.q : ({ good: 0, uncertain: 1, bad: 2 }[row.tag.quality] ?? 0);
      setText(row.value, formatValue(value, row.tag));
      row.value.className = `live-value ${qualityClass(quality)}`;
      setText(row.quality, qualityName(quality));
      row.quality.className = `qual ${qualityName(quality)}`;
      setText(row.time, formatTime(item ? item.t : row.tag.timestamp));
      showForced(row.forced, item ? item.f : row.tag.forced);
    }
  }

  const filter = () => {
    const text = search.value.trim().toLowerCase();
    const chosen = group.value;
    rows = all.filter((tag) => (!chosen || (tag.group || '(no group)') === chosen || (tag.group || '').startsWith(`${chosen}/`))
      && (!text || tag.name.toLowerCase().includes(text)));
    body.scrollTop = 0;
    render();
  };
  search.addEventListener('input', filter);
  group.addEventListener('change', filter);
  body.addEventListener('scroll', () => requestAnimationFrame(render), { passive: true });
  const resize = () => render();
  window.addEventListener('resize', resize);
  filter();
  root.dataset.ready = '1';
  return () => {
    watch.close();
    clearTimeout(subscribeTimer);
    window.removeEventListener('resize', resize);
  };
}
