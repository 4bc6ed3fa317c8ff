// Robots: the fleet (navigation state and reason, pose, speed, load, task, sim/remote/online)
// and the robot-task compatibility matrix with the reasons a robot cannot serve a task.

import { el, setText } from '../dom.js';
import { get, tagsWithPrefix } from '../api.js';
import { formatNumber, NAVSTATE_CLASS, CURRLOC_TEXT } from '../format.js';
import { robotColor } from '../overview/floor.js';

export async function mount(root, ctx) {
  const model = await get('/api/robots');
  const fields = new Map();  // robot id → {field: node}
  const cards = model.robots.map((robot, index) => {
    const nodes = {};
    const cell = (key) => (nodes[key] = el('dd', { class: 'num live-value', text: '—' }));
    const state = el('span', { class: 'chip idle', text: '…' });
    nodes.state = state;
    const swatch = el('span', { class: 'task-dot' });
    swatch.style.background = robotColor(index);
    const card = el('section', { class: 'panel robot-panel', 'data-robot': robot.id },
      el('div', { class: 'panel-head' }, el('h2', {}, swatch, ` ${robot.id} · ${robot.name}`), state),
      el('dl', { class: 'kv' },
        el('dt', { text: 'why' }), cell('reason'),
        el('dt', { text: 'pose' }), cell('pose'),
        el('dt', { text: 'speed' }), cell('speed'),
        el('dt', { text: 'load' }), cell('load'),
        el('dt', { text: 'task' }), cell('task'),
        el('dt', { text: 'driver' }), cell('driver'),
        el('dt', { text: 'hardware' }), el('dd', { class: 'small', text: robot.hardware.join(', ').replaceAll('_', ' ') }),
        el('dt', { text: 'size' }), el('dd', { class: 'small', text: `${robot.size_mm.join(' × ')} mm · ≤ ${robot.max_linear_speed} m/s, ${robot.max_angular_speed} rad/s` }),
      ),
      el('button', { type: 'button', class: 'btn small secondary', text: 'All tags…', onclick: async () => {
        ctx.openDetails(`Robot ${robot.id} — ${robot.name}`, await tagsWithPrefix(`${robot.id}_`));
      } }));
    fields.set(robot.id, nodes);
    return card;
  });

  const head = el('tr', {}, el('th', { text: 'robot' }), ...model.tasks.map((task) => el('th', { text: `${task.id} · ${task.name}` })));
  const rows = model.robots.map((robot) => el('tr', { 'data-robot': robot.id }, el('th', { text: robot.id }), ...model.tasks.map((task) => {
    const entry = (model.compatibility[robot.id] || {})[task.id] || { ok: false, why: ['unknown'] };
    return entry.ok
      ? el('td', { class: 'yes', 'data-task': task.id, text: '✓ can serve' })
      : el('td', { class: 'no', 'data-task': task.id }, '✗ cannot', el('span', { class: 'why', text: entry.why.join('; ') }));
  })));
  const needs = model.tasks.map((task) => el('li', { text: `${task.id}: requires ${task.requires.join(', ').replaceAll('_', ' ') || 'nothing special'}; robots up to ${task.limits.max_size_mm.join(' × ')} mm, load ≥ ${task.limits.min_load_capacity}, ≥ ${task.limits.min_linear_speed} m/s; team of at most ${task.max_team_size}` }));
  root.append(
    el('div', { class: 'grid-cards live-content' }, ...cards),
    el('section', { class: 'panel' }, el('h2', { text: 'Which robot can serve which task' }),
      el('div', { class: 'scroll-x' }, el('table', { class: 'data matrix' }, el('thead', {}, head), el('tbody', {}, ...rows))),
      el('ul', { class: 'small muted' }, ...needs)),
  );

  const names = model.robots.flatMap((robot) => Object.values(robot.tags));
  const update = () => {
    const value = (name) => { const item = name ? ctx.live.get(name) : undefined; return item ? item.v : undefined; };
    for (const robot of model.robots) {
      const nodes = fields.get(robot.id);
      const tags = robot.tags;
      const quality = ctx.live.get(tags.xpos);
      const online = tags.online ? value(tags.online) !== false : true;
      const offline = (quality && quality.q === 2) || ((robot.driver === 'remote' || robot.driver === 'vda5050') && !online);
      const navstate = offline ? 'offline' : (value(tags.navstate) || 'idle');
      nodes.state.className = `chip ${NAVSTATE_CLASS[navstate] || 'idle'}`;
      setText(nodes.state, navstate);
      setText(nodes.reason, value(tags.navreason) || '—');
      const x = value(tags.xpos), y = value(tags.ypos), heading = value(tags.heading);
      setText(nodes.pose, typeof x === 'number' ? `x ${formatNumber(x, 2)} m, y ${formatNumber(y, 2)} m, ${formatNumber((heading || 0) * 180 / Math.PI, 0)}°` : '—');
      setText(nodes.speed, typeof value(tags.speed) === 'number' ? `${formatNumber(value(tags.speed), 2)} m/s` : '—');
      setText(nodes.load, typeof value(tags.load) === 'number' ? `${value(tags.load)} / ${value(tags.loadcap) ?? robot.load_capacity} items` : '—');
      const current = value(tags.tcurr), where = value(tags.currloc) || 0;
      setText(nodes.task, current ? `task ${current}: ${CURRLOC_TEXT[where] || ''}` : 'none');
      const kind = { remote: 'remote agent', vda5050: 'VDA 5050 vehicle' }[robot.driver];
      setText(nodes.driver, kind ? `${kind} · ${online ? 'online' : 'OFFLINE'}` : 'simulated in the runtime');
      for (const node of [nodes.pose, nodes.speed]) node.classList.toggle('q-bad', Boolean(quality && quality.q === 2));
    }
  };
  const watch = ctx.live.watch(names, update);
  update();
  root.dataset.ready = '1';
  return () => watch.close();
}
