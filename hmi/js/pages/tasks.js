// Tasks and programs: the runtime state, each task's live scan statistics, each program's state
// and last error, and the reset commands for the roles allowed to send them; program control and
// online change for engineers (ops/programs.js).

import { el, setText } from '../dom.js';
import { get, tagMeta } from '../api.js';
import { formatNumber } from '../format.js';
import { decoratePrograms } from '../ops/programs.js';
import { mountSparkplug } from './sparkplug_panel.js';
import { linksPanel } from './links_panel.js';

const SERIES = [['scan', 'scan time'], ['cycle', 'cycle time'], ['latency', 'start latency']];
const STATS = ['min', 'mean', 'p99', 'max'];

export async function mount(root, ctx) {
  const model = await get('/api/tasks');
  const cells = new Map();  // tag → {node, kind}
  const bind = (tag, node, kind) => { cells.set(tag, { node, kind }); return node; };

  const state = bind(model.state, el('span', { class: 'chip idle live-value', text: '…' }), 'state');
  const error = bind(model.error, el('p', { class: 'error-text', text: '' }), 'error');
  const time = bind(model.time, el('span', { class: 'num live-value' }), 'time');
  const actions = el('div', { class: 'toolbar' });
  for (const [key, label] of [['reset_faults', 'Reset faults'], ['reset_stats', 'Reset statistics']]) {
    const command = model[key];
    if (!command.writable) continue;
    actions.append(el('button', { type: 'button', class: 'btn secondary', text: `${label}…`, 'data-command': key, onclick: async () => {
      const [meta] = await tagMeta([command.tag]);
      ctx.openWrite(meta, true);
    } }));
  }
  if (!actions.childElementCount) actions.append(el('span', { class: 'muted small', text: `Resetting faults needs the operator or engineer role (you are ${ctx.session.role}).` }));

  const runtime = el('section', { class: 'panel' },
    el('div', { class: 'panel-head' }, el('h1', {}, 'Runtime '), state),
    el('dl', { class: 'kv' }, el('dt', { text: 'Runtime clock' }), el('dd', {}, time, ctx.session.simulated ? ' (simulated)' : '')),
    error, actions);

  const cards = model.tasks.map((task) => {
    const table = el('table', { class: 'data stat-table num' },
      el('thead', {}, el('tr', {}, el('th', { text: 'ms' }), ...STATS.map((stat) => el('th', { class: 'num', text: stat })))));
    const tbody = el('tbody');
    for (const [series, label] of SERIES) {
      tbody.append(el('tr', {}, el('th', { text: label }), ...STATS.map((stat) => bind(`${task.prefix}${series}_ms_${stat}`, el('td', { class: 'num live-value', text: '—' }), 'ms'))));
    }
    table.append(tbody);
    const counters = el('dl', { class: 'kv small' });
    for (const [counter, label] of [['cycles', 'cycles'], ['overruns', 'overruns'], ['watchdog_trips', 'watchdog trips']]) {
      counters.append(el('dt', { text: label }), bind(`${task.prefix}${counter}`, el('dd', { class: 'num live-value', text: '—' }), 'count'));
    }
    const programs = task.programs.map((program) => el('div', { class: 'program', 'data-program': program.name },
      el('strong', { text: program.name }),
      bind(`${program.prefix}state`, el('span', { class: 'chip idle', text: '…' }), 'program-state'),
      el('span', { class: 'ref muted small', text: program.program }),
      el('span', { class: 'ref small' }, bind(`${program.prefix}faults`, el('span', { class: 'muted', text: '' }), 'faults')),
      bind(`${program.prefix}error`, el('span', { class: 'ref error-text small', text: '' }), 'error'),
    ));
    return el('section', { class: 'panel', 'data-task': task.name },
      el('div', { class: 'panel-head' }, el('h2', { text: `Task ${task.name}` }),
        el('span', { class: 'muted small', text: `every ${formatNumber(task.interval_ms)} ms · priority ${task.priority} · watchdog ${formatNumber(task.watchdog_ms)} ms` })),
      el('div', { class: 'scroll-x' }, table), counters,
      el('h3', { text: `Programs (${task.programs.length})` }), ...programs);
  });
  root.append(runtime, el('div', { class: 'grid-cards wide live-content' }, ...cards));
  const links = await linksPanel();  // the links to other controllers and their health, when the plant has any
  if (links) {
    root.append(links.node);
    for (const tag of links.cells.keys()) cells.set(tag, { node: null, kind: 'link', update: links.cells.get(tag) });
  }

  const update = (names) => {
    for (const name of names) {
      const cell = cells.get(name);
      const item = ctx.live.get(name);
      if (!cell || !item) continue;
      const value = item.v;
      switch (cell.kind) {
        case 'link':
          cell.update(value);
          break;
        case 'state':
          cell.node.className = `chip live-value ${value === 'RUNNING' ? 'ok' : value === 'ERROR' ? 'bad' : 'warn'}`;
          setText(cell.node, value);
          break;
        case 'program-state':
          cell.node.className = `chip ${value === 'RUNNING' ? 'ok' : value === 'FAULTED' ? 'bad' : 'idle'}`;
          setText(cell.node, value);
          break;
        case 'error':
          setText(cell.node, value ? `last error: ${value}` : '');
          break;
        case 'faults':
          setText(cell.node, value ? `${value} fault${value === 1 ? '' : 's'}` : '');
          break;
        case 'time':
          setText(cell.node, `${formatNumber(value, 1)} s`);
          break;
        case 'ms':  // about three significant digits: 0.152, 2.68, 100.6, 1022
          setText(cell.node, formatNumber(value, value < 1 ? 3 : value < 10 ? 2 : value < 100 ? 1 : 0));
          break;
        default:
          setText(cell.node, formatNumber(value));
      }
    }
  };
  const watch = ctx.live.watch([...cells.keys()], update);
  update([...cells.keys()]);
  const undecorate = await decoratePrograms(root, ctx, model);  // start / stop / restart, online change (engineers)
  const unmountSparkplug = await mountSparkplug(runtime, ctx);  // the Sparkplug B edge node, when the plant has one
  root.dataset.ready = '1';
  return () => { watch.close(); undecorate(); unmountSparkplug(); };
}
