// The Sparkplug B edge node on the Tasks page: its connection to the broker, the primary host's
// state, bdSeq, births, what it published, stored and refused. Live from the `_sys.sparkplug.*`
// tags; the broker and ids from the `sparkplug.status` query. Nothing when the plant has no
// `sparkplug:` section.

import { el, setText } from '../dom.js';
import { tagsWithPrefix } from '../api.js';
import { command } from '../commands.js';
import { formatNumber } from '../format.js';

const PREFIX = '_sys.sparkplug.';
const ROWS = [
  ['connected', 'Broker connection', 'connection'],
  ['primary_host_online', 'Primary host', 'host'],
  ['bdseq', 'bdSeq (session)', 'count'],
  ['births', 'Births', 'count'],
  ['messages', 'Messages published', 'count'],
  ['metrics', 'Metric values published', 'count'],
  ['stored', 'Stored, to forward', 'count'],
  ['dropped', 'Dropped (store full)', 'count'],
  ['commands', 'Command metrics applied', 'count'],
  ['refused', 'Commands refused', 'count'],
  ['last_refusal', 'Last refusal', 'text'],
];

/** Mount the panel after `anchor` when the plant has an edge node; returns an undo. */
export async function mountSparkplug(anchor, ctx) {
  const tags = await tagsWithPrefix(PREFIX);
  if (!tags.length) return () => {};
  const status = await command('sparkplug.status');  // refused or unknown when the edge node is off (e.g. --sim)
  const info = status.ok ? status.result : null;
  const cells = new Map();
  const bind = (name, node, kind) => { cells.set(PREFIX + name, { node, kind }); return node; };
  const state = bind('state', el('span', { class: 'chip idle', text: '…' }), 'state');
  const list = el('dl', { class: 'kv' });
  if (info) {
    list.append(el('dt', { text: 'Broker' }), el('dd', { class: 'ref', text: info.broker }),
      el('dt', { text: 'Group / edge node' }), el('dd', { class: 'ref', text: `${info.group_id} / ${info.edge_node_id}` }),
      el('dt', { text: 'Devices' }), el('dd', { text: Object.entries(info.devices).map(([id, n]) => `${id} (${n})`).join(', ') }));
  }
  for (const [name, label, kind] of ROWS) {
    if (name === 'primary_host_online' && info && !info.primary_host) continue;
    const value = bind(name, el('dd', { class: kind === 'count' ? 'num live-value' : 'live-value', text: '—' }), kind);
    list.append(el('dt', { text: name === 'primary_host_online' && info ? `Primary host ${info.primary_host}` : label }), value);
  }
  const panel = el('section', { class: 'panel', 'data-panel': 'sparkplug' },
    el('div', { class: 'panel-head' }, el('h2', {}, 'Sparkplug B edge node '), state), list);
  anchor.after(panel);

  const update = (names) => {
    for (const name of names) {
      const cell = cells.get(name);
      const item = ctx.live.get(name);
      if (!cell || !item) continue;
      const value = item.v;
      switch (cell.kind) {
        case 'state':
          cell.node.className = `chip ${value === 'online' ? 'ok' : value === 'off' ? 'idle' : 'warn'}`;
          setText(cell.node, value);
          break;
        case 'connection':
          cell.node.className = `live-value ${value ? '' : 'error-text'}`;
          setText(cell.node, value ? 'connected' : 'disconnected');
          break;
        case 'host':
          cell.node.className = `live-value ${value ? '' : 'error-text'}`;
          setText(cell.node, value ? 'online' : 'offline');
          break;
        case 'text':
          setText(cell.node, value || '—');
          break;
        default:
          setText(cell.node, formatNumber(value));
      }
    }
  };
  const watch = ctx.live.watch([...cells.keys()], update);
  update([...cells.keys()]);
  return () => { watch.close(); panel.remove(); };
}
