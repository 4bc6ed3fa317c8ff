// The overview's side: one card per task (buffer levels, fill rates, weight, goals, its robots)
// and one line per robot (state, task, load), with the bottleneck and the next task marked.

import { el, setText } from '../dom.js';
import { formatNumber, formatWithUnit, NAVSTATE_CLASS, CURRLOC_TEXT } from '../format.js';
import { taskColor, robotColor } from './floor.js';
import { forcedMark, showForced, anyForced } from '../ops/forcing.js';

function level(label, kind) {
  const fill = el('div', { class: `fill ${kind}` });
  const text = el('span', { class: 'num live-value' });
  const mark = forcedMark(false);
  return { node: el('div', { class: 'level' }, el('div', { class: 'label' }, el('span', {}, label, ' ', mark), text), el('div', { class: 'track' }, fill)), fill, text, mark };
}

function figure(label) {
  const value = el('b', { class: 'num live-value', text: '—' });
  const mark = forcedMark(false);
  return { node: el('div', {}, el('span', { class: 'muted' }, label, ' ', mark), value), value, mark };
}

export class TaskCards {
  constructor(fleet, live, onOpen) {
    this.fleet = fleet;
    this.live = live;
    this.cards = fleet.tasks.map((task, index) => this._card(task, index, onOpen));
    this.node = el('div', { class: 'task-cards side-stack live-content' }, ...this.cards.map((card) => card.node));
  }

  names() {
    const names = [];
    for (const task of this.fleet.tasks) names.push(...Object.values(task.tags));
    for (const robot of this.fleet.robots) for (const field of ['tcurr', 'currloc', 'status']) if (robot.tags[field]) names.push(robot.tags[field]);
    return names;
  }

  _card(task, index, onOpen) {
    const input = level('Input buffer', 'in');
    const output = level('Output storage', 'out');
    const rate = figure('fill rate');
    const weight = figure('weight Tw');
    const goals = figure('goals');
    const badges = el('span', { class: 'badges' });
    const note = el('p', { class: 'task-note small', hidden: true });
    const robots = el('div', { class: 'small muted team' });
    const node = el('section', { class: 'panel task-card', 'data-task': task.id, tabindex: 0, role: 'button', 'aria-label': `${task.name}: details` },
      el('div', { class: 'title' }, el('span', { class: 'task-dot' }), el('h2', { text: `${task.name}` }), el('span', { class: 'muted small', text: task.id }), badges),
      note, input.node, output.node,
      el('div', { class: 'task-figures' }, rate.node, weight.node, goals.node),
      robots,
    );
    node.querySelector('.task-dot').style.background = taskColor(index);  // CSSOM: allowed by the CSP, unlike style=""
    node.addEventListener('click', () => onOpen(task));
    node.addEventListener('keydown', (event) => { if (event.key === 'Enter') onOpen(task); });
    return { task, index, node, input, output, rate, weight, goals, badges, note, robots };
  }

  update() {
    const value = (name) => { const item = name ? this.live.get(name) : undefined; return item ? item.v : undefined; };
    let fullest = null, lightest = null;
    for (const card of this.cards) {
      const tags = card.task.tags;
      this._level(card.input, value(tags.iBM), value(tags.iBC), value(tags.iBL), true);
      this._level(card.output, value(tags.qSM), value(tags.qSC), value(tags.qSL), false);
      setText(card.rate.value, tags.iFr ? `${formatNumber(value(tags.iFr) ?? NaN, 1)}/min` : '—');
      setText(card.weight.value, tags.Tw && typeof value(tags.Tw) === 'number' ? formatNumber(value(tags.Tw), 2) : '—');
      setText(card.goals.value, tags.goals && value(tags.goals) !== undefined ? String(value(tags.goals)) : '—');
      showForced(card.input.mark, anyForced(this.live, [tags.iBM, tags.iBL, tags.iBC]));
      showForced(card.output.mark, anyForced(this.live, [tags.qSM, tags.qSL, tags.qSC]));
      showForced(card.rate.mark, anyForced(this.live, [tags.iFr]));
      showForced(card.weight.mark, anyForced(this.live, [tags.Tw]));
      showForced(card.goals.mark, anyForced(this.live, [tags.goals]));
      // The team as the dispatchers count it (programs/teams.py): robots sent to the task's source
      // until they have unloaded at its destination (currloc 1-4).
      const serving = [];
      this.fleet.robots.forEach((robot) => {
        const where = value(robot.tags.currloc) || 0;
        if (value(robot.tags.tcurr) === card.task.number && where >= 1 && where <= 4) serving.push(`${robot.id} ${CURRLOC_TEXT[where]}`);
      });
      const limit = card.task.max_team_size || 0;
      card.team = { size: serving.length, limit, full: limit > 0 && serving.length >= limit };
      const size = limit > 0 ? ` (${serving.length}/${limit})` : '';
      setText(card.robots, serving.length ? `Team${size}: ${serving.join(' · ')}` : `No robot on this task now${limit > 0 ? ` (team of at most ${limit})` : ''}`);
      const inLevel = value(tags.iBL);
      if (typeof inLevel === 'number' && (!fullest || inLevel > fullest.level)) fullest = { card, level: inLevel };
      const tw = value(tags.Tw);
      card.tw = typeof tw === 'number' ? tw : null;
      // The next free robot goes to the lowest weight among the tasks whose team has room.
      if (card.tw !== null && !card.team.full) {
        if (!lightest || card.tw < lightest.tw) lightest = { card, tw: card.tw, tie: false };
        else if (card.tw === lightest.tw) lightest.tie = true;
      }
    }
    const next = lightest && !lightest.tie && this.cards.length > 1 ? lightest.card : null;
    for (const card of this.cards) {
      const bottleneck = fullest && fullest.card === card && fullest.level >= 50;
      const team = card.team;
      const nextHere = next === card;
      // Why the next robot goes elsewhere, where an operator would expect it here: the bottleneck,
      // or the lowest weight of all, whose team is full.
      const lowest = card.tw !== null && this.cards.every((other) => other.tw === null || other.tw >= card.tw);
      let why = '';
      if (!nextHere && (bottleneck || lowest)) {
        const elsewhere = next ? `the next free robot goes to ${next.task.name}` : 'no task has room for another robot';
        if (team.full) why = `Its team is full (${team.size}/${team.limit}): ${elsewhere}.`;
        else if (bottleneck && next && card.tw !== null) why = `Weight ${formatNumber(card.tw, 2)} is not the lowest: ${elsewhere} (weight ${formatNumber(next.tw, 2)}).`;
      }
      card.note.hidden = !why;
      setText(card.note, why);
      const key = `${bottleneck}|${nextHere}|${team.full}|${team.size}/${team.limit}`;
      if (card.badges.dataset.key === key) continue;
      card.badges.dataset.key = key;
      card.badges.replaceChildren(
        ...(bottleneck ? [el('span', { class: 'badge bottleneck', title: 'The fullest input buffer: production here is the first to stall', text: 'bottleneck' })] : []),
        ...(nextHere ? [el('span', { class: 'badge next', title: 'Lowest task weight among the tasks whose team has room: the next free robot goes here', text: 'next robot' })] : []),
        ...(team.full ? [el('span', { class: 'badge full', title: `${team.size} robots serve this task, its most (max_team_size): no other robot is sent here until one has unloaded`, text: `team full ${team.size}/${team.limit}` })] : []),
      );
    }
  }

  _level(bar, items, capacity, percent, input) {
    let level = percent;
    if (typeof level !== 'number' && typeof items === 'number' && typeof capacity === 'number' && capacity > 0) level = 100 * items / capacity;
    if (typeof level !== 'number') { setText(bar.text, '—'); return; }
    const clamped = Math.max(0, Math.min(100, level));
    bar.fill.style.width = `${clamped}%`;
    bar.fill.classList.toggle('high', input && level >= 80 && level < 95);
    bar.fill.classList.toggle('full', input && level >= 95);
    const count = typeof items === 'number' ? (typeof capacity === 'number' ? `${items} / ${capacity} items · ` : `${items} items · `) : '';
    setText(bar.text, `${count}${formatNumber(level, 0)} %`);
  }
}

export class RobotList {
  constructor(fleet, live, onOpen) {
    this.fleet = fleet;
    this.live = live;
    this.rows = fleet.robots.map((robot, index) => {
      const state = el('span', { class: 'chip idle', text: 'idle' });
      const line2 = el('div', { class: 'line2' });
      const swatch = el('span', { class: 'swatch', text: robot.id.replace(/^[a-z]+/i, '') || robot.id });
      swatch.style.background = robotColor(index);
      const mark = forcedMark(false);
      const node = el('div', { class: 'robot-card', 'data-robot': robot.id, tabindex: 0, role: 'button', 'aria-label': `Robot ${robot.id}: details` },
        swatch, el('strong', {}, `${robot.id} · ${robot.name} `, mark), state, line2);
      node.addEventListener('click', () => onOpen(robot));
      node.addEventListener('keydown', (event) => { if (event.key === 'Enter') onOpen(robot); });
      return { robot, node, state, line2, mark };
    });
    this.node = el('div', { class: 'robot-list live-content' }, ...this.rows.map((row) => row.node));
  }

  names() {
    return this.fleet.robots.flatMap((robot) => Object.values(robot.tags));
  }

  update() {
    const value = (name) => { const item = name ? this.live.get(name) : undefined; return item ? item.v : undefined; };
    for (const row of this.rows) {
      const tags = row.robot.tags;
      const quality = this.live.get(tags.xpos);
      const online = tags.online ? value(tags.online) !== false : true;
      const away = row.robot.driver === 'remote' || row.robot.driver === 'vda5050';  // robots that report, and can stop
      const offline = (quality && quality.q === 2) || (away && !online);
      const navstate = offline ? 'offline' : (value(tags.navstate) || 'idle');
      row.state.className = `chip ${NAVSTATE_CLASS[navstate] || 'idle'}`;
      setText(row.state, navstate);
      const parts = [];
      const current = value(tags.tcurr);
      const where = value(tags.currloc) || 0;
      if (current && (where > 0 || value(tags.status))) parts.push(`task ${current}: ${CURRLOC_TEXT[where] || ''}`);
      else parts.push('no task');
      if (typeof value(tags.load) === 'number') parts.push(`load ${value(tags.load)}/${value(tags.loadcap) ?? row.robot.load_capacity}`);
      if (typeof value(tags.speed) === 'number') parts.push(formatWithUnit(value(tags.speed), 'm/s', 2));
      if (away) parts.push(`${row.robot.driver === 'remote' ? 'remote' : 'VDA 5050'}, ${online ? 'online' : 'OFFLINE'}`);
      const reason = value(tags.navreason);
      if (reason && (navstate === 'blocked' || navstate === 'failed')) parts.push(reason);
      setText(row.line2, parts.join(' · '));
      showForced(row.mark, anyForced(this.live, Object.values(tags)));
    }
  }
}
