// The Tasks page's links panel: the plant's links to other controllers (the links: section) and
// their health, live — state, why a link is down or late, bound tags that are not good,
// reconnects, round trip — from the links.list query and the _sys.links.NAME.* tags. Each link
// lists its bound tags (links.tags) with their quality and the reason when it is not good. A
// plant without links (or whose links are off) shows nothing.

import { el, setText } from '../dom.js';
import { command } from '../commands.js';
import { tagsWithPrefix } from '../api.js';
import { formatNumber } from '../format.js';

const STATES = { up: 'ok', late: 'warn', connecting: 'idle', down: 'bad' };
const QUALITIES = { good: 'ok', uncertain: 'warn', bad: 'bad' };

/** The panel (or null without links) and the live tags it shows: {node, cells: Map tag → update(value)}. */
export async function linksPanel() {
  if (!(await tagsWithPrefix('_sys.links.')).length) return null;  // no links: no query (it is unknown, a 404)
  const answer = await command('links.list');
  if (!answer.ok || !Array.isArray(answer.result) || !answer.result.length) return null;
  const cells = new Map();
  const live = (tag, node, update) => { cells.set(tag, (value) => update(node, value)); return node; };
  const text = (node, value) => setText(node, value);
  const count = (node, value) => setText(node, formatNumber(value));
  const rows = answer.result.map((link) => {
    const state = live(`${link.prefix}state`, el('span', { class: 'chip idle', text: link.state }), (node, value) => {
      node.className = `chip ${STATES[value] || 'idle'}`;
      setText(node, value);
    });
    const details = el('details', { class: 'link-tags' }, el('summary', { class: 'small', text: `${link.tags} bound tag${link.tags === 1 ? '' : 's'}` }));
    details.addEventListener('toggle', () => { if (details.open) showTags(details, link.name); });
    return el('tr', { 'data-link': link.name },
      el('td', { class: 'link-name' }, el('strong', { text: link.name }), el('div', { class: 'muted small ref', text: `${link.protocol} ${link.address}` }),
        el('div', { class: 'muted small', text: `every ${formatNumber(link.period_ms)} ms` })),
      el('td', { class: 'link-state' }, state, live(`${link.prefix}error`, el('div', { class: 'error-text small', text: link.error }), text)),
      el('td', { class: 'num', 'data-label': 'bad tags' }, live(`${link.prefix}bad_tags`, el('span', { text: formatNumber(link.bad_tags) }), count)),
      el('td', { class: 'num', 'data-label': 'reconnects' }, live(`${link.prefix}reconnects`, el('span', { text: formatNumber(link.reconnects) }), count)),
      el('td', { class: 'num', 'data-label': 'round trip ms' }, live(`${link.prefix}round_trip_ms`, el('span', { text: formatNumber(link.round_trip_ms, 2) }),
        (node, value) => setText(node, formatNumber(value, 2)))),
      el('td', {}, details));
  });
  const table = el('table', { class: 'data links' },
    el('thead', {}, el('tr', {}, ...['link', 'state', 'bad tags', 'reconnects', 'round trip ms', 'tags'].map((name, index) =>
      el('th', { class: index >= 2 && index <= 4 ? 'num' : '', text: name })))),
    el('tbody', {}, ...rows));
  const node = el('section', { class: 'panel', 'data-panel': 'links' },
    el('div', { class: 'panel-head' }, el('h2', { text: `Links to other controllers (${rows.length})` })),
    el('div', { class: 'scroll-x' }, table));
  return { node, cells };
}

async function showTags(details, link) {
  const old = details.querySelector('.link-tags-table');
  if (old) old.remove();
  const answer = await command('links.tags', { link });
  if (!answer.ok) {
    details.append(el('p', { class: 'error-text small', text: answer.error }));
    return;
  }
  const body = el('tbody', {}, ...answer.result.map((row) => el('tr', { 'data-tag': row.tag },
    el('td', { text: row.tag }), el('td', { class: 'ref small', text: row.source }), el('td', { text: row.direction }),
    el('td', {}, el('span', { class: `chip ${QUALITIES[row.quality] || 'idle'}`, text: row.quality })),
    el('td', { class: 'small', text: row.reason }))));
  details.append(el('div', { class: 'scroll-x link-tags-table' }, el('table', { class: 'data small' },
    el('thead', {}, el('tr', {}, ...['tag', 'source', 'direction', 'quality', 'why'].map((name) => el('th', { text: name })))), body)));
}

