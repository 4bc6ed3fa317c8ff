// The factory floor: the ROS map, each task's stations with their buffer levels, and every robot
// at its pose with heading, route, goal, navigation state and current task, moving smoothly.
// Layers, bottom up: map, flows, station footprints, routes, goals, robots, then what must stay
// readable above them — the stations' texts and bars, the robots' labels (placed clear of every
// other label: labels.js).

import { svg, setText } from '../dom.js';
import { anyForced } from '../ops/forcing.js';
import { formatNumber } from '../format.js';
import { Station, GOAL_RING } from './stations.js';
import { placeLabels } from './labels.js';

export const SCALE = 40;  // SVG units per metre: a 22 m floor is ~880 units, about its size on screen
export const TASK_COLORS = ['#3056a8', '#b4471d', '#6d28d9', '#0f766e', '#a21caf', '#4d7c0f', '#9f1239', '#1e40af'];
export const ROBOT_COLORS = ['#7e22ce', '#d97706', '#0e7490', '#be123c', '#15803d', '#4338ca', '#a16207', '#0369a1', '#c026d3', '#4d7c0f'];
const MARKER = 0.3;       // m: a robot is drawn at least this big, so it can be seen and clicked
const SMOOTHING = 0.15;   // s: time constant of the marker following its pose
const SNAP = 3.0;         // m: a jump this long is shown at once (a robot placed elsewhere)
const AT_STATION = 0.6;   // m: a goal this close to a station is that station (outlined, not crossed)
const LABEL_HEIGHT = 17;

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
    const root = svg('svg', { class: 'floor live-content', viewBox: `0 0 ${width.toFixed(1)} ${height.toFixed(1)}`, role: 'img',
      'aria-label': `Factory floor, ${formatNumber(this.bounds.w)} m by ${formatNumber(this.bounds.h)} m, with stations and robots` });
    if (this.fleet.map) {
      root.append(svg('image', { href: this.fleet.map.url, x: 0, y: 0, width, height, preserveAspectRatio: 'none' }));
    }
    const grid = svg('g', { class: 'grid', 'aria-hidden': 'true' });
    for (let x = Math.ceil(this.bounds.x / 5) * 5; x <= this.bounds.x + this.bounds.w; x += 5) {
      grid.append(svg('text', { x: this.X(x) + 3, y: height - 4, 'font-size': 10, fill: '#8a94a3', text: `${x} m` }));
    }
    const layer = (name) => svg('g', { class: name });
    const flows = layer('flows'), footprints = layer('footprints'), routes = layer('routes'), goals = layer('goals');
    const robots = layer('robots'), stations = layer('stations'), leaders = layer('leaders'), labels = layer('robot-labels');
    this.fleet.tasks.forEach((task, index) => {
      const color = taskColor(index);
      const flow = svg('line', { class: 'flow', stroke: color });
      flows.append(flow);
      const make = (kind, fallback, x, y, items, level, capacity) => (fallback || (task.tags[x] && task.tags[y])
        ? new Station(task, kind, color, fallback, { x, y, items, level, capacity }, this.handlers.task) : null);
      const source = make('in', task.source, 'src_x', 'src_y', 'iBM', 'iBL', 'iBC');
      const target = make('out', task.destination, 'dest_x', 'dest_y', 'qSM', 'qSL', 'qSC');
      for (const station of [source, target]) if (station) { footprints.append(station.footprint); stations.append(station.node); }
      this.stations.push({ task, flow, source, target });
    });
    this.fleet.robots.forEach((robot, index) => {
      const marker = this._robot(robot, robotColor(index));
      routes.append(marker.route);
      goals.append(marker.goal);
      robots.append(marker.node);
      leaders.append(marker.leader);
      labels.append(marker.tag);
      this.robots.set(robot.id, marker);
    });
    root.append(grid, flows, footprints, routes, goals, robots, stations, leaders, labels);
    return root;
  }

  _robot(robot, color) {
    const radius = Math.max(robot.radius || 0.18, MARKER) * SCALE;
    const ring = svg('circle', { class: 'ring idle', r: radius + 3 });
    const body = svg('circle', { r: radius, fill: color, stroke: '#fff', 'stroke-width': 2 });
    const nose = svg('path', { d: `M ${radius * 0.2} ${-radius * 0.55} L ${radius * 1.25} 0 L ${radius * 0.2} ${radius * 0.55} Z`, fill: '#fff' });
    const heading = svg('g', { class: 'heading' }, nose);
    const node = svg('g', { class: 'robot', 'data-robot': robot.id, tabindex: 0, role: 'button', 'aria-label': `Robot ${robot.id}, ${robot.name}` },
      ring, body, heading);
    // Its label, drawn above stations and other robots: name, task badge ("T2"), red F.
    const label = svg('text', { class: 'robot-label', x: 0, y: 13, fill: color, text: robot.id });
    const taskBox = svg('rect', { y: 0, width: 30, height: LABEL_HEIGHT, rx: 4, fill: '#56627a' });
    const taskText = svg('text', { class: 'robot-task', x: 15, y: 12.5, 'text-anchor': 'middle', text: '' });
    const badge = svg('g', { class: 'task-badge', visibility: 'hidden' }, taskBox, taskText);
    const forced = svg('g', { class: 'forced-badge', visibility: 'hidden' },
      svg('rect', { y: 1, width: 14, height: 15, rx: 3 }), svg('text', { x: 7, y: 12.5, 'text-anchor': 'middle', text: 'F' }));
    const tag = svg('g', { class: 'robot-tag', 'data-robot': robot.id }, label, badge, forced);
    for (const target of [node, tag]) {
      target.addEventListener('click', () => this.handlers.robot(robot));
      target.addEventListener('keydown', (event) => { if (event.key === 'Enter') this.handlers.robot(robot); });
    }
    const leader = svg('line', { class: 'robot-leader', stroke: color, visibility: 'hidden' });
    const route = svg('polyline', { class: 'route', stroke: color, points: '' });
    const goal = svg('path', { class: 'goal', stroke: color, d: '', visibility: 'hidden', 'data-robot': robot.id });
    return { robot, node, ring, heading, radius: radius + 3, label, badge, taskBox, taskText, forced, tag, leader, route, goal,
      offset: [-robot.id.length * 4, -radius - 3 - 3 - LABEL_HEIGHT], gap: 0, target: null, shown: null };
  }

  /** Apply changed values (names from the live channel). */
  update() {
    const live = this.live;
    const value = (name) => { const item = name ? live.get(name) : undefined; return item ? item.v : undefined; };
    const width = this.bounds.w * SCALE;
    for (const { flow, source, target } of this.stations) {
      for (const station of [source, target]) if (station) station.place(value, live, (x) => this.X(x), (y) => this.Y(y), width);
      if (source && target && source.at && target.at) {
        flow.setAttribute('x1', source.at[0]); flow.setAttribute('y1', source.at[1]);
        flow.setAttribute('x2', target.at[0]); flow.setAttribute('y2', target.at[1]);
      }
    }
    const numbers = new Map(this.fleet.tasks.map((task, index) => [task.number, { task, index }]));
    const goalsAt = new Map();  // station → robots heading there (each outline a little larger)
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
      marker.tag.classList.toggle('offline', offline);
      const navstate = offline ? 'offline' : (value(tags.navstate) || 'idle');
      marker.ring.setAttribute('class', `ring ${navstate}`);
      marker.node.dataset.navstate = navstate;
      const current = value(tags.tcurr);
      const busy = value(tags.status) || (value(tags.currloc) || 0) > 0;
      const entry = numbers.get(current);
      marker.hasTask = Boolean(current && entry && busy);
      if (marker.hasTask) {
        setText(marker.taskText, `T${current}`);
        marker.taskBox.setAttribute('fill', taskColor(entry.index));
      }
      marker.badge.setAttribute('visibility', marker.hasTask ? 'visible' : 'hidden');
      marker.isForced = anyForced(live, Object.values(tags));
      marker.forced.setAttribute('visibility', marker.isForced ? 'visible' : 'hidden');
      const route = value(tags.route);
      marker.route.setAttribute('points', typeof route === 'string' ? this._points(route) : '');
      const gx = value(tags.xgoal), gy = value(tags.ygoal);
      const moving = navstate === 'moving' || navstate === 'planning' || navstate === 'blocked';
      if (typeof gx === 'number' && typeof gy === 'number' && moving) {
        const X = this.X(gx), Y = this.Y(gy);
        const station = this._stationAt(gx, gy);
        if (station) {
          const count = goalsAt.get(station) || 0;
          goalsAt.set(station, count + 1);
          const half = GOAL_RING + 4 * Math.min(count, 1);
          const [SX, SY] = station.at;
          marker.goal.setAttribute('d', `M ${SX - half} ${SY - half} h ${2 * half} v ${2 * half} h ${-2 * half} Z`);
          marker.goal.classList.add('at-station');
        } else {
          marker.goal.setAttribute('d', `M ${X - 6} ${Y - 6} L ${X + 6} ${Y + 6} M ${X - 6} ${Y + 6} L ${X + 6} ${Y - 6}`);
          marker.goal.classList.remove('at-station');
        }
        marker.goalBox = station ? null : [X - 8, Y - 8, X + 8, Y + 8];
        marker.goal.setAttribute('visibility', 'visible');
      } else {
        marker.goalBox = null;
        marker.goal.setAttribute('visibility', 'hidden');
      }
    }
    this._placeLabels();
    this._animate();
  }

  /** The station whose point is within AT_STATION of (x, y) m, or null. */
  _stationAt(x, y) {
    for (const { source, target } of this.stations) {
      for (const station of [source, target]) {
        if (station && station.at && station.point && Math.hypot(station.point.x - x, station.point.y - y) <= AT_STATION) return station;
      }
    }
    return null;
  }

  /** Lay the robots' labels out (where their robots are going to be) clear of everything else. */
  _placeLabels() {
    const markers = [...this.robots.values()].filter((marker) => marker.target);
    const obstacles = [];
    for (const { source, target } of this.stations) for (const station of [source, target]) if (station) obstacles.push(...station.obstacles());
    for (const marker of markers) if (marker.goalBox) obstacles.push(marker.goalBox);
    const robots = markers.map((marker) => {
      if (!marker.nameWidth) {  // measured once it is laid out (a robot's name does not change)
        let measured = 0;
        try { measured = marker.label.getComputedTextLength(); } catch { measured = 0; }
        if (measured > 0) marker.nameWidth = measured;
      }
      const nameWidth = marker.nameWidth || 8.2 * marker.robot.id.length;
      marker.badge.setAttribute('transform', `translate(${(nameWidth + 4).toFixed(1)} 0)`);
      const afterBadge = nameWidth + (marker.hasTask ? 34 : 0);
      marker.forced.setAttribute('transform', `translate(${(afterBadge + 4).toFixed(1)} 0)`);
      const width = afterBadge + (marker.isForced ? 18 : 0);
      return { x: this.X(marker.target.x), y: this.Y(marker.target.y), ring: marker.radius, width, height: LABEL_HEIGHT };
    });
    const bounds = [0, 0, this.bounds.w * SCALE, this.bounds.h * SCALE];
    placeLabels(robots, obstacles, bounds).forEach(({ box, gap }, index) => {
      const marker = markers[index];
      marker.offset = [box[0] - robots[index].x, box[1] - robots[index].y];
      marker.size = [box[2] - box[0], box[3] - box[1]];
      marker.gap = gap;
    });
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
      const X = this.X(shown.x), Y = this.Y(shown.y);
      marker.node.setAttribute('transform', `translate(${X.toFixed(1)} ${Y.toFixed(1)})`);
      marker.heading.setAttribute('transform', `rotate(${(-shown.heading * 180 / Math.PI).toFixed(1)})`);
      marker.node.dataset.x = shown.x.toFixed(3);
      marker.node.dataset.y = shown.y.toFixed(3);
      this._moveLabel(marker, X, Y);
    }
    if (moving) this._frame = requestAnimationFrame((next) => this._step(next));
  }

  /** The label goes with its robot; pushed out further than beside it, a leader line joins them. */
  _moveLabel(marker, X, Y) {
    const [dx, dy] = marker.offset;
    marker.tag.setAttribute('transform', `translate(${(X + dx).toFixed(1)} ${(Y + dy).toFixed(1)})`);
    if (marker.gap <= 3 || !marker.size) {
      marker.leader.setAttribute('visibility', 'hidden');
      return;
    }
    // From the ring's edge to the nearest point of the label.
    const nx = Math.max(X + dx, Math.min(X, X + dx + marker.size[0])), ny = Math.max(Y + dy, Math.min(Y, Y + dy + marker.size[1]));
    const length = Math.hypot(nx - X, ny - Y) || 1;
    marker.leader.setAttribute('x1', (X + (nx - X) * marker.radius / length).toFixed(1));
    marker.leader.setAttribute('y1', (Y + (ny - Y) * marker.radius / length).toFixed(1));
    marker.leader.setAttribute('x2', nx.toFixed(1));
    marker.leader.setAttribute('y2', ny.toFixed(1));
    marker.leader.setAttribute('visibility', 'visible');
  }

  stop() {
    if (this._frame !== null) cancelAnimationFrame(this._frame);
    this._frame = null;
  }
}

function boundsOf(fleet) {
  const xs = [], ys = [];
  for (const task of fleet.tasks) for (const point of [task.source, task.destination]) if (point) { xs.push(point.x); ys.push(point.y); }
  if (!xs.length) return { x: 0, y: 0, w: 20, h: 10 };
  const x = Math.min(...xs) - 2, y = Math.min(...ys) - 2;
  return { x, y, w: Math.max(...xs) + 2 - x, h: Math.max(...ys) + 2 - y };
}
