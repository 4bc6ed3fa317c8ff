// VDA 5050 vehicles on the overview: the roadmap drawn on the floor (lanes and nodes), each vehicle's
// order (its base solid — released, the nodes it may drive — and its horizon dashed — planned, not
// released), and a panel with each vehicle's connection, liveness, what traffic holds it for and its
// errors. The roadmap comes from the runtime's `vda5050.roadmap` query (a viewer may call it); the
// orders and states from the live `_sys.vda5050.<robot>.*` tags, so nothing is polled.

import { el, svg, setText } from '../dom.js';
import { command } from '../commands.js';
import { formatNumber } from '../format.js';
import { robotColor } from './floor.js';

const FIELDS = ['base', 'horizon', 'connection', 'error', 'rejected', 'waiting', 'battery', 'mode', 'estop', 'paused'];

/** The VDA 5050 layer, or null when the plant drives no VDA 5050 vehicle (no `vda5050.roadmap` query). */
export async function vda5050Layer(floor, fleet, live) {
  const vehicles = fleet.robots.map((robot, index) => ({ robot, index })).filter(({ robot }) => robot.driver === 'vda5050');
  if (!vehicles.length) return null;
  const answer = await command('vda5050.roadmap');
  if (!answer.ok) return null;
  return new Vda5050Layer(floor, vehicles, live, answer.result);
}

class Vda5050Layer {
  constructor(floor, vehicles, live, roadmap) {
    this.floor = floor;
    this.live = live;
    this.nodes = new Map(roadmap.nodes.map((node) => [node.id, node]));
    const X = (x) => floor.X(x).toFixed(1), Y = (y) => floor.Y(y).toFixed(1);
    const lanes = svg('g', { class: 'roadmap', 'aria-hidden': 'true' });
    for (const lane of roadmap.lanes) {
      const a = this.nodes.get(lane.from), b = this.nodes.get(lane.to);
      if (a && b) lanes.append(svg('line', { x1: X(a.x), y1: Y(a.y), x2: X(b.x), y2: Y(b.y), stroke: '#9aa5b5', 'stroke-width': 2,
        'stroke-dasharray': lane.one_way ? '2 3' : null, 'stroke-linecap': 'round' }));
    }
    for (const node of roadmap.nodes) {
      lanes.append(svg('circle', { cx: X(node.x), cy: Y(node.y), r: node.station ? 5 : 3.5, fill: '#fff', stroke: '#6b7687', 'stroke-width': 1.5 }),
        svg('text', { x: (Number(X(node.x)) + 6).toFixed(1), y: (Number(Y(node.y)) - 5).toFixed(1), 'font-size': 9, fill: '#6b7687', text: node.id }));
    }
    this.orders = svg('g', { class: 'vda-orders' });
    const flows = floor.node.querySelector('g.flows');
    floor.node.insertBefore(lanes, flows);
    floor.node.insertBefore(this.orders, flows);
    this.vehicles = vehicles.map(({ robot, index }) => this._vehicle(robot, robotColor(index)));
    this.broker = el('span', { class: 'small muted live-value', text: '' });
    this.node = el('section', { class: 'panel vda-panel' },
      el('h2', {}, 'VDA 5050 vehicles ', this.broker),
      el('table', { class: 'mini-tags' },
        el('thead', {}, el('tr', {}, ...['robot', 'connection', 'order: base → horizon', 'battery', 'waiting / errors'].map((text) => el('th', { text })))),
        el('tbody', {}, ...this.vehicles.map((vehicle) => vehicle.row))),
      el('p', { class: 'small muted', text: 'On the floor: the roadmap in grey; each vehicle\'s base (released) solid, its horizon (planned) dashed.' }));
  }

  _vehicle(robot, color) {
    const prefix = `_sys.vda5050.${robot.id}`;
    const base = svg('polyline', { fill: 'none', stroke: color, 'stroke-width': 5, 'stroke-linecap': 'round', 'stroke-linejoin': 'round', opacity: 0.75, points: '' });
    const horizon = svg('polyline', { fill: 'none', stroke: color, 'stroke-width': 3, 'stroke-dasharray': '8 6', opacity: 0.75, points: '' });
    this.orders.append(horizon, base);
    const cells = { connection: el('td'), order: el('td', { class: 'small' }), battery: el('td', { class: 'num' }), notes: el('td', { class: 'small' }) };
    const row = el('tr', { 'data-robot': robot.id }, el('td', { text: robot.id }), cells.connection, cells.order, cells.battery, cells.notes);
    return { robot, prefix, base, horizon, row, cells };
  }

  names() {
    const names = ['_sys.vda5050.broker'];
    for (const vehicle of this.vehicles) {
      names.push(...FIELDS.map((field) => `${vehicle.prefix}.${field}`));
      if (vehicle.robot.tags.online) names.push(vehicle.robot.tags.online);
    }
    return names;
  }

  update() {
    const value = (name) => { const item = this.live.get(name); return item ? item.v : undefined; };
    const broker = value('_sys.vda5050.broker');
    setText(this.broker, broker === false ? '— the MQTT broker is unreachable' : '');
    this.broker.classList.toggle('error-text', broker === false);
    for (const vehicle of this.vehicles) {
      const get = (field) => value(`${vehicle.prefix}.${field}`);
      const base = String(get('base') || '').split(/\s+/).filter(Boolean);
      const horizon = String(get('horizon') || '').split(/\s+/).filter(Boolean);
      vehicle.base.setAttribute('points', this._points(base));
      vehicle.horizon.setAttribute('points', this._points(base.length ? [base[base.length - 1], ...horizon] : horizon));
      const online = vehicle.robot.tags.online ? value(vehicle.robot.tags.online) : undefined;
      const connection = get('connection') || '—';
      setText(vehicle.cells.connection, online === false ? `lost (${connection})` : connection);
      vehicle.cells.connection.className = online === false ? 'error-text' : '';
      setText(vehicle.cells.order, base.length ? `${base.join(' ')}${horizon.length ? ' → ' + horizon.join(' ') : ''}` : '—');
      const battery = get('battery');
      setText(vehicle.cells.battery, typeof battery === 'number' && online !== false ? `${formatNumber(battery, 0)} %` : '—');
      const notes = [get('paused') ? 'paused' : '', get('waiting') ? `waits: ${get('waiting')}` : '', get('rejected') ? `rejected: ${get('rejected')}` : '',
        get('error') || '', get('estop') && get('estop') !== 'NONE' ? `e-stop ${get('estop')}` : '',
        get('mode') && get('mode') !== 'AUTOMATIC' ? get('mode') : ''].filter(Boolean);
      setText(vehicle.cells.notes, notes.join('; ') || '—');
      vehicle.cells.notes.className = get('error') || get('rejected') ? 'small error-text' : 'small';
    }
  }

  _points(ids) {
    return ids.map((id) => this.nodes.get(id)).filter(Boolean)
      .map((node) => `${this.floor.X(node.x).toFixed(1)},${this.floor.Y(node.y).toFixed(1)}`).join(' ');
  }
}
