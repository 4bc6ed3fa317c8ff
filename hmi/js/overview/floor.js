// The factory floor: the ROS map, each task's stations with their buffer levels, and every robot
// at its pose with heading, route, goal, navigation state and current task, moving smoothly.

import { svg, setText } from '../dom.js';
import { anyForced } from '../ops/forcing.js';
import { formatNumber } from '../format.js';

export const SCALE = 40;  // SVG units per metre: a 22 m floor is ~880 units, about its size on screen
export const TASK_COLORS = ['#3056a8', '#b4471d', '#6d28d9', '#0f766e', '#a21caf', '#4d7c0f', '#9f1239', '#1e40af'];
export const ROBOT_COLORS = ['#7e22ce', '#d97706', '#0e7490', '#be123c', '#15803d', '#4338ca', '#a16207', '#0369a1', '#c026d3', '#4d7c0f'];
const MARKER = 0.3;       // m: a robot is drawn at least this big, so it can be seen and clicked
const SMOOTHING = 0.15;   // s: time constant of the marker following its pose
const SNAP = 3.0;         // m: a jump this long is shown at once (a robot placed elsewhere)

export function robotColor(index) { return ROBOT_COLORS[index % ROBOT_COLORS.length]; }
export function taskColor(index) { return TASK_COLORS[index % TASK_COLORS.length]; }

export class Floor {
  constructor(fleet, live, handlers) {
    this.fleet = fleet;
    this.live = live;
    this.handlers = handlers;
    const map = fleet.map;
    this.bounds = map ? { x: map.origin_x, y: map.origin_y, w: map.width, h: map.height } : boundsOf(fleet);
    this.robots = new Map();
    this.stations = [];
    this._frame = null;
    this._last = 0;
    this.node = this._draw();
  }

  X(x) { return (x - this.bounds.x) * SCALE; }
  Y(y) { return (this.bounds.h - (y - this.bounds.y)) * SCALE; }

  /** Every tag the floor shows. */
  names() {
    const names = [];
    for (const robot of this.fleet.robots) names.push(...Object.values(robot.tags));
    for (const task of this.fleet.tasks) {
      for (const field of ['iBM', 'iBL', 'iBC', 'iFr', 'qSM', 'qSL', 'qSC', 'src_x', 'src_y', 'dest_x', 'dest_y']) {
        if (task.tags[field]) names.push(task.tags[field]);
      }
    }
    return names;
  }

  _draw() {
    const width = this.bounds.w * SCALE;
    const height = this.bounds.h * SCALE;
    const root = svg('svg', { class: 'floor', viewBox: `0 0 ${width.toFixed(1)} ${height.toFixed(1)}`, role: 'img',
      'aria-label': `Factory floor, ${formatNumber(this.bounds.w)} m by ${formatNumber(this.bounds.h)} m, with stations and robots` });
    if (this.fleet.map) {
      root.append(svg('image', { href: this.fleet.map.url, x: 0, y: 0, width, height, preserveAspectRatio: 'none' }));
    }
    const grid = svg('g', { class: 'grid', 'aria-hidden': 'true' });
    for (let x = Math.ceil(this.bounds.x / 5) * 5; x <= this.bounds.x + this.bounds.w; x += 5) {
      grid.append(svg('text', { x: this.X(x) + 3, y: height - 4, 'font-size': 10, fill: '#8a94a3', text: `${x} m` }));
    }
    root.append(grid);
    const flows = svg('g', { class: 'flows' });
    const stations = svg('g', { class: 'stations' });
    this.fleet.tasks.forEach((task, index) => {
      const color = taskColor(index);
      const flow = svg('line', { class: 'flow', stroke: color });
      flows.append(flow);
      const source = this._station(task, 'in', color, task.source, 'src_x', 'src_y', 'iBM', 'iBL', 'iBC');
      const target = this._station(task, 'out', color, task.destination, 'dest_x', 'dest_y', 'qSM', 'qSL', 'qSC');
      for (const station of [source, target]) if (station) stations.append(station.node);
      this.stations.push({ task, flow, source, target });
    });
    root.append(flows, stations);
    const routes = svg('g', { class: 'routes' });
    const robots = svg('g', { class: 'robots' });
    this.fleet.robots.forEach((robot, index) => {
      const marker = this._robot(robot, robotColor(index));
      routes.append(marker.route, marker.goal);
      robots.append(marker.node);
      this.robots.set(robot.id, marker);
    });
    root.append(routes, robots);
    return root;
  }

  _station(task, kind, color, fallback, xField, yField, itemsField, levelField, capacityField) {
    if (!fallback && !(task.tags[xField] && task.tags[yField])) return null;
    const short = `T${task.number ?? task.id}`;
    const box = svg('rect', { class: 'station-box', x: -16, y: -16, width: 32, height: 32, rx: 5, fill: color, stroke: '#fff' });
    const label = svg('text', { class: 'station-label', x: 0, y: 5, 'text-anchor': 'middle', text: kind === 'in' ? 'IN' : 'OUT' });
    const name = svg('text', { class: 'bar-text', x: 0, y: -22, 'text-anchor': 'middle', text: short });
    const forced = forcedBadge(-23, 6);  // on the box's lower left corner: inside the map wherever the station is
    const node = svg('g', { class: 'station', 'data-task': task.id, 'data-kind': kind, tabindex: 0, role: 'button',
      'aria-label': `${task.name} ${kind === 'in' ? 'input buffer' : 'output storage'}` }, box, label, name, forced);
    let bar = null;
    if (task.tags[levelField] || task.tags[itemsField]) {
      const track = svg('rect', { class: 'bar-track', x: 24, y: -36, width: 18, height: 72, rx: 3 });
      const fill = svg('rect', { class: 'bar-fill', x: 26, y: 34, width: 14, height: 0, rx: 2, fill: kind === 'in' ? '#2e6fd1' : '#2f9e5b',
        'data-level': 0, 'data-tag': task.tags[levelField] || task.tags[itemsField] });
      const count = svg('text', { class: 'bar-text', x: 48, y: -22, text: '' });
      const percent = svg('text', { class: 'bar-text', x: 48, y: 34, text: '' });
      const rate = svg('text', { class: 'bar-text rate', x: 33, y: 54, 'text-anchor': 'middle', text: '' });
      node.append(track, fill, count, percent, rate);
      bar = { fill, count, percent, rate };
    }
    node.addEventListener('click', () => this.handlers.task(task));
    node.addEventListener('keydown', (event) => { if (event.key === 'Enter') this.handlers.task(task); });
    return { node, bar, kind, fallback, xField, yField, itemsField, levelField, capacityField, task, forced };
  }

  _robot(robot, color) {
    const radius = Math.max(robot.radius || 0.18, MARKER) * SCALE;
    const ring = svg('circle', { class: 'ring idle', r: radius + 3 });
    const body = svg('circle', { r: radius, fill: color, stroke: '#fff', 'stroke-width': 2 });
    const nose = svg('path', { d: `M ${radius * 0.2} ${-radius * 0.55} L ${radius * 1.25} 0 L ${radius * 0.2} ${radius * 0.55} Z`, fill: '#fff' });
    const heading = svg('g', { class: 'heading' }, nose);
    const label = svg('text', { class: 'robot-label', x: 0, y: -radius - 7, 'text-anchor': 'middle', fill: color, text: robot.id });
    const taskBox = svg('rect', { x: radius + 2, y: 2, width: 30, height: 17, rx: 4, fill: '#56627a' });
    const taskText = svg('text', { class: 'robot-task', x: radius + 17, y: 14.5, 'text-anchor': 'middle', text: '' });
    const badge = svg('g', { class: 'task-badge', visibility: 'hidden' }, taskBox, taskText);
    const forced = forcedBadge(-radius - 16, -radius - 20);
    const node = svg('g', { class: 'robot', 'data-robot': robot.id, tabindex: 0, role: 'button', 'aria-label': `Robot ${robot.id}, ${robot.name}` },
      ring, body, heading, label, badge, forced);
    node.addEventListener('click', () => this.handlers.robot(robot));
    node.addEventListener('keydown', (event) => { if (event.key === 'Enter') this.handlers.robot(robot); });
    const route = svg('polyline', { class: 'route', stroke: color, points: '' });
    const goal = svg('path', { class: 'goal', stroke: color, d: '', visibility: 'hidden' });
    return { robot, node, ring, heading, badge, taskBox, taskText, route, goal, forced, target: null, shown: null };
  }

  /** Apply changed values (names from the live channel). */
  update() {
    const live = this.live;
    const value = (name) => { const item = name ? live.get(name) : undefined; return item ? item.v : undefined; };
    for (const { task, flow, source, target } of this.stations) {
      for (const station of [source, target]) if (station) this._placeStation(station, value);
      if (source && target && source.at && target.at) {
        flow.setAttribute('x1', source.at[0]); flow.setAttribute('y1', source.at[1]);
        flow.setAttribute('x2', target.at[0]); flow.setAttribute('y2', target.at[1]);
      }
    }
    const numbers = new Map(this.fleet.tasks.map((task, index) => [task.number, { task, index }]));
    for (const marker of this.robots.values()) {
      const tags = marker.robot.tags;
      const x = value(tags.xpos), y = value(tags.ypos);
      if (typeof x === 'number' && typeof y === 'number') {
        const heading = typeof value(tags.heading) === 'number' ? value(tags.heading) : 0;
        marker.target = { x, y, heading };
        if (!marker.shown) marker.shown = { ...marker.target };
      }
      const quality = live.get(tags.xpos);
      const reporting = marker.robot.driver === 'remote' || marker.robot.driver === 'vda5050';  // robots that can be away
      const online = reporting && tags.online ? value(tags.online) !== false : true;
      const offline = (quality && quality.q === 2) || !online;
      marker.node.classList.toggle('offline', offline);
      const navstate = offline ? 'offline' : (value(tags.navstate) || 'idle');
      marker.ring.setAttribute('class', `ring ${navstate}`);
      marker.node.dataset.navstate = navstate;
      const current = value(tags.tcurr);
      const busy = value(tags.status) || (value(tags.currloc) || 0) > 0;
      const entry = numbers.get(current);
      if (current && entry && busy) {
        setText(marker.taskText, `T${current}`);
        marker.taskBox.setAttribute('fill', taskColor(entry.index));
        marker.badge.setAttribute('visibility', 'visible');
      } else {
        marker.badge.setAttribute('visibility', 'hidden');
      }
      marker.forced.setAttribute('visibility', anyForced(live, Object.values(tags)) ? 'visible' : 'hidden');
      const route = value(tags.route);
      marker.route.setAttribute('points', typeof route === 'string' ? this._points(route) : '');
      const gx = value(tags.xgoal), gy = value(tags.ygoal);
      const moving = navstate === 'moving' || navstate === 'planning' || navstate === 'blocked';
      if (typeof gx === 'number' && typeof gy === 'number' && moving) {
        const X = this.X(gx), Y = this.Y(gy);
        marker.goal.setAttribute('d', `M ${X - 6} ${Y - 6} L ${X + 6} ${Y + 6} M ${X - 6} ${Y + 6} L ${X + 6} ${Y - 6}`);
        marker.goal.setAttribute('visibility', 'visible');
      } else {
        marker.goal.setAttribute('visibility', 'hidden');
      }
    }
    this._animate();
  }

  _placeStation(station, value) {
    const tags = station.task.tags;
    const x = value(tags[station.xField]) ?? (station.fallback && station.fallback.x);
    const y = value(tags[station.yField]) ?? (station.fallback && station.fallback.y);
    if (typeof x !== 'number' || typeof y !== 'number') return;
    const X = this.X(x), Y = this.Y(y);
    // Keep the bar on the map: beside the station on the right, or on the left near the edge.
    const flip = X + 100 > this.bounds.w * SCALE;
    station.node.setAttribute('transform', `translate(${X.toFixed(1)} ${Y.toFixed(1)})${flip ? ' scale(1 1)' : ''}`);
    station.at = [X, Y];
    if (!station.bar) return;
    if (flip && !station.flipped) {
      station.flipped = true;
      for (const node of station.node.querySelectorAll('.bar-track, .bar-fill')) node.setAttribute('x', Number(node.getAttribute('x')) - 66 - Number(node.getAttribute('width')) + 18);
      for (const node of [station.bar.count, station.bar.percent]) { node.setAttribute('x', -48); node.setAttribute('text-anchor', 'end'); }
      station.bar.rate.setAttribute('x', -33);
    }
    const items = value(tags[station.itemsField]);
    const capacity = value(tags[station.capacityField]);
    let level = value(tags[station.levelField]);
    if (typeof level !== 'number' && typeof items === 'number' && typeof capacity === 'number' && capacity > 0) level = 100 * items / capacity;
    if (typeof level === 'number') {
      const clamped = Math.max(0, Math.min(100, level));
      const height = 68 * clamped / 100;
      station.bar.fill.setAttribute('height', height.toFixed(1));
      station.bar.fill.setAttribute('y', (34 - height).toFixed(1));
      station.bar.fill.dataset.level = level.toFixed(1);
      if (station.kind === 'in') station.bar.fill.setAttribute('fill', level >= 95 ? '#b3261e' : level >= 80 ? '#d08a00' : '#2e6fd1');
      setText(station.bar.percent, `${formatNumber(level, 0)}%`);
    }
    if (typeof items === 'number') setText(station.bar.count, typeof capacity === 'number' ? `${items}/${capacity}` : String(items));
    const rate = station.kind === 'in' ? value(tags.iFr) : undefined;  // items arriving per minute
    if (typeof rate === 'number') setText(station.bar.rate, `+${formatNumber(rate, rate % 1 ? 1 : 0)}/min`);
    const shown = [station.itemsField, station.levelField, station.capacityField, station.xField, station.yField, station.kind === 'in' ? 'iFr' : null];
    station.forced.setAttribute('visibility', anyForced(this.live, shown.map((field) => field && tags[field])) ? 'visible' : 'hidden');
    const quality = this.live.get(tags[station.levelField] || tags[station.itemsField]);
    station.node.classList.toggle('q-bad', Boolean(quality && quality.q === 2));
  }

  _points(route) {
    const points = [];
    for (const pair of route.trim().split(/\s+/)) {
      const [x, y] = pair.split(',').map(Number);
      if (Number.isFinite(x) && Number.isFinite(y)) points.push(`${this.X(x).toFixed(1)},${this.Y(y).toFixed(1)}`);
    }
    return points.join(' ');
  }

  _animate() {
    if (this._frame !== null) return;
    this._last = performance.now();
    this._frame = requestAnimationFrame((now) => this._step(now));
  }

  _step(now) {
    this._frame = null;
    const dt = Math.min(0.25, (now - this._last) / 1000);
    this._last = now;
    const follow = 1 - Math.exp(-dt / SMOOTHING);
    let moving = false;
    for (const marker of this.robots.values()) {
      const target = marker.target, shown = marker.shown;
      if (!target || !shown) continue;
      const dx = target.x - shown.x, dy = target.y - shown.y;
      let turn = target.heading - shown.heading;
      turn = Math.atan2(Math.sin(turn), Math.cos(turn));
      if (Math.hypot(dx, dy) > SNAP) {
        Object.assign(shown, target);
      } else {
        shown.x += dx * follow; shown.y += dy * follow; shown.heading += turn * follow;
        if (Math.abs(dx) > 0.002 || Math.abs(dy) > 0.002 || Math.abs(turn) > 0.002) moving = true;
        else Object.assign(shown, target);
      }
      marker.node.setAttribute('transform', `translate(${this.X(shown.x).toFixed(1)} ${this.Y(shown.y).toFixed(1)})`);
      marker.heading.setAttribute('transform', `rotate(${(-shown.heading * 180 / Math.PI).toFixed(1)})`);
      marker.node.dataset.x = shown.x.toFixed(3);
      marker.node.dataset.y = shown.y.toFixed(3);
    }
    if (moving) this._frame = requestAnimationFrame((next) => this._step(next));
  }

  stop() {
    if (this._frame !== null) cancelAnimationFrame(this._frame);
    this._frame = null;
  }
}

/** A red "F" in a box at (x, y) of its group: shown while a tag the group draws is forced. */
function forcedBadge(x, y) {
  return svg('g', { class: 'forced-badge', visibility: 'hidden', transform: `translate(${x} ${y})` },
    svg('rect', { width: 14, height: 15, rx: 3 }), svg('text', { x: 7, y: 11.5, 'text-anchor': 'middle', text: 'F' }));
}

function boundsOf(fleet) {
  const xs = [], ys = [];
  for (const task of fleet.tasks) for (const point of [task.source, task.destination]) if (point) { xs.push(point.x); ys.push(point.y); }
  if (!xs.length) return { x: 0, y: 0, w: 20, h: 10 };
  const x = Math.min(...xs) - 2, y = Math.min(...ys) - 2;
  return { x, y, w: Math.max(...xs) + 2 - x, h: Math.max(...ys) + 2 - y };
}
