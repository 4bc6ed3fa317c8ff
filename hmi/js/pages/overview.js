// Plant overview: the thesis's mimic (Fig. 5.3), live. With a fleet: the factory floor with
// stations, buffer levels and robots, beside one card per task and the robot list. Without one:
// each tag group with a few live values.

import { el, setText } from '../dom.js';
import { get, tagsWithPrefix } from '../api.js';
import { formatWithUnit, qualityClass } from '../format.js';
import { Floor } from '../overview/floor.js';
import { TaskCards, RobotList } from '../overview/cards.js';
import { vda5050Layer } from '../overview/vda5050.js';

export async function mount(root, ctx) {
  const plant = await get('/api/plant');
  if (plant.fleet && plant.fleet.robots.length) return mountFleet(root, ctx, plant);
  return mountGroups(root, ctx, plant);
}

const DRIVERS = { remote: 'remote robot agent', vda5050: 'VDA 5050 vehicle (MQTT)', sim: 'simulated in the runtime' };

async function mountFleet(root, ctx, plant) {
  const fleet = plant.fleet;
  const openRobot = async (robot) => {
    const tags = await tagsWithPrefix(`${robot.id}_`);
    const vehicle = robot.driver === 'vda5050' ? await tagsWithPrefix(`_sys.vda5050.${robot.id}.`) : [];
    ctx.openDetails(`Robot ${robot.id} — ${robot.name}`, [...tags, ...vehicle], `${DRIVERS[robot.driver] || robot.driver} · hardware: ${robot.hardware.join(', ').replaceAll('_', ' ')}`);
  };
  const openTask = async (task) => {
    const tags = await tagsWithPrefix(`${task.id}_`);
    ctx.openDetails(`${task.name} (${task.id})`, tags, `requires ${task.requires.join(', ').replaceAll('_', ' ') || 'nothing special'} · team of at most ${task.max_team_size}`);
  };
  const floor = new Floor(fleet, ctx.live, { robot: openRobot, task: openTask });
  const cards = new TaskCards(fleet, ctx.live, openTask);
  const robots = new RobotList(fleet, ctx.live, openRobot);
  const vehicles = await vda5050Layer(floor, fleet, ctx.live);  // null without VDA 5050 vehicles
  const clock = el('span', { class: 'muted small num live-value' });
  root.append(el('div', { class: 'overview' },
    el('section', { class: 'panel floor-panel' },
      el('div', { class: 'floor-head' }, el('h1', { text: plant.name }), clock),
      el('div', { class: 'floor-scroll' }, floor.node),
      el('div', { class: 'legend' },
        el('span', {}, el('i', { class: 'sw-src' }), 'input buffer level'),
        el('span', {}, el('i', { class: 'sw-dst' }), 'output storage level'),
        el('span', {}, el('i', { class: 'sw-route' }), 'robot route; goal: ✕, or a dashed square round its station'),
        el('span', { text: 'ring: green moving · blue planning · amber blocked · red failed · grey idle' }),
        el('span', { text: 'click a robot or a station for its tags' }),
        el('span', { class: 'phone-only', text: 'drag the floor sideways to see all of it' }),
      ),
      robots.node,
      vehicles ? vehicles.node : null),
    el('div', { class: 'side' }, cards.node),
  ));
  const names = [...new Set([...floor.names(), ...cards.names(), ...robots.names(), ...(vehicles ? vehicles.names() : []), '_sys.time'])];
  const update = () => {
    floor.update();
    if (vehicles) vehicles.update();
    cards.update();
    robots.update();
    const time = ctx.live.get('_sys.time');
    if (time) setText(clock, `plant time ${formatWithUnit(time.v, 's', 1)}${ctx.session.simulated ? ' (simulated)' : ''}`);
  };
  const watch = ctx.live.watch(names, update);
  const ready = () => { update(); root.dataset.ready = '1'; };
  if (ctx.live.synced) ready();
  ctx.live.addEventListener('synced', ready);
  return () => {
    watch.close();
    floor.stop();
    ctx.live.removeEventListener('synced', ready);
  };
}

function mountGroups(root, ctx, plant) {
  const cells = new Map();
  const cards = plant.groups.filter((group) => !group.name.startsWith('_sys')).map((group) => {
    const body = el('tbody');
    for (const name of group.preview) {
      const value = el('td', { class: 'v live-value' });
      body.append(el('tr', {}, el('td', { text: name }), value));
      cells.set(name, value);
    }
    return el('section', { class: 'panel group-card' },
      el('h3', {}, el('span', { text: group.name }), el('a', { href: `#/tags?group=${encodeURIComponent(group.name)}`, text: `${group.count} tags →` })),
      el('table', { class: 'mini-tags' }, body));
  });
  root.append(
    el('div', { class: 'panel' }, el('h1', { text: plant.name }), plant.description ? el('p', { class: 'muted', text: plant.description }) : null,
      el('p', { class: 'small muted', text: `This plant has no robot fleet: here are its tag groups. The Tags page lists every tag${
        ctx.session.pages.some((page) => page.group === 'Views') ? '; the views show the mimics drawn for it' : ''}.` })),
    el('div', { class: 'grid-cards' }, ...cards),
  );
  const units = new Map();
  const update = (names) => {
    for (const name of names) {
      const cell = cells.get(name);
      const item = ctx.live.get(name);
      if (!cell || !item) continue;
      setText(cell, formatWithUnit(item.v, units.get(name)));
      cell.className = `v live-value ${qualityClass(item.q)}`;
    }
  };
  const watch = ctx.live.watch([...cells.keys()], update);
  get(`/api/tags?names=${encodeURIComponent([...cells.keys()].join(','))}`).then((data) => {
    for (const tag of data.tags) units.set(tag.name, tag.unit);
    update([...cells.keys()]);
  });
  const ready = () => { update([...cells.keys()]); root.dataset.ready = '1'; };
  if (ctx.live.synced) ready();
  ctx.live.addEventListener('synced', ready);
  return () => { watch.close(); ctx.live.removeEventListener('synced', ready); };
}
