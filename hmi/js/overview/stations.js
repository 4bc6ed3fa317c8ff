// A task's station on the factory floor: its footprint (the square a robot parks on) drawn under
// the robots, and its information drawn above them — the name ("T1 IN") under the square, the
// level bar beside it with the items, the fill rate and the level in a column, the red F on the
// other side — so a robot standing at the station never hides what the station says. Laid out
// so nothing overlaps a goal outline (±25 units) or another text; the bar side flips to the left
// near the map's right edge.

import { svg, setText } from '../dom.js';
import { anyForced } from '../ops/forcing.js';
import { formatNumber } from '../format.js';

const HALF = 16;            // the footprint's half side (SVG units)
const BAR = [30, 18];       // the bar's distance from the centre and its width
const BAR_HALF = 36;        // the bar's half height
const COLUMN = 54;          // the texts beside the bar: distance from the centre
const NEEDS_RIGHT = 112;    // what the bar and its texts need on their side
export const GOAL_RING = 20;  // a goal outline's half side (a second goal on the same station: 4 more)

/** Draw one station; `place` puts it at its position once the values are known. */
export class Station {
  constructor(task, kind, color, fallback, fields, open) {
    this.task = task;
    this.kind = kind;
    this.fallback = fallback;
    this.fields = fields;  // {x, y, items, level, capacity}
    this.at = null;
    this.side = 0;
    const short = `T${task.number ?? task.id}`;
    const label = `${task.name} ${kind === 'in' ? 'input buffer' : 'output storage'}`;
    const box = svg('rect', { class: 'station-box', x: -HALF, y: -HALF, width: 2 * HALF, height: 2 * HALF, rx: 5, fill: color, stroke: '#fff' });
    this.footprint = svg('g', { class: 'station-footprint', 'data-task': task.id, 'data-kind': kind, 'aria-hidden': 'true' }, box);
    this.name = svg('text', { class: 'bar-text station-name', x: 0, y: 41, 'text-anchor': 'middle', text: `${short} ${kind === 'in' ? 'IN' : 'OUT'}` });
    this.forced = svg('g', { class: 'forced-badge', visibility: 'hidden' },
      svg('rect', { width: 14, height: 15, rx: 3 }), svg('text', { x: 7, y: 11.5, 'text-anchor': 'middle', text: 'F' }));
    this.node = svg('g', { class: 'station', 'data-task': task.id, 'data-kind': kind, tabindex: 0, role: 'button', 'aria-label': label },
      this.name, this.forced);
    this.bar = null;
    if (task.tags[fields.level] || task.tags[fields.items]) {
      const track = svg('rect', { class: 'bar-track', y: -BAR_HALF, width: BAR[1], height: 2 * BAR_HALF, rx: 3 });
      const fill = svg('rect', { class: 'bar-fill', y: BAR_HALF - 2, width: BAR[1] - 4, height: 0, rx: 2, fill: kind === 'in' ? '#2e6fd1' : '#2f9e5b',
        'data-level': 0, 'data-tag': task.tags[fields.level] || task.tags[fields.items] });
      const count = svg('text', { class: 'bar-text', y: -26, text: '' });
      const rate = svg('text', { class: 'bar-text rate', y: 5, text: '' });
      const percent = svg('text', { class: 'bar-text', y: 36, text: '' });
      this.node.append(track, fill, count, rate, percent);
      this.bar = { track, fill, count, rate, percent };
    }
    for (const target of [this.node, this.footprint]) {
      target.addEventListener('click', () => open(task));
      target.addEventListener('keydown', (event) => { if (event.key === 'Enter') open(task); });
    }
    this._layout(1);
  }

  /** The bar and its texts on the right (1) or the left (-1) of the footprint, the F on the other side. */
  _layout(side) {
    if (side === this.side) return;
    this.side = side;
    this.forced.setAttribute('transform', `translate(${side > 0 ? -BAR[0] - 14 : BAR[0]} -7)`);
    if (!this.bar) return;
    const { track, fill, count, rate, percent } = this.bar;
    const left = side > 0 ? BAR[0] : -BAR[0] - BAR[1];
    track.setAttribute('x', left);
    fill.setAttribute('x', left + 2);
    for (const text of [count, rate, percent]) {
      text.setAttribute('x', side * COLUMN);
      text.setAttribute('text-anchor', side > 0 ? 'start' : 'end');
    }
  }

  /** Position and values from the live tags (`value(name)`), on a map `width` units wide. */
  place(value, live, X, Y, width) {
    const tags = this.task.tags;
    const x = value(tags[this.fields.x]) ?? (this.fallback && this.fallback.x);
    const y = value(tags[this.fields.y]) ?? (this.fallback && this.fallback.y);
    if (typeof x !== 'number' || typeof y !== 'number') return;
    const at = [X(x), Y(y)];
    this.at = at;
    this.point = { x, y };
    const transform = `translate(${at[0].toFixed(1)} ${at[1].toFixed(1)})`;
    this.node.setAttribute('transform', transform);
    this.footprint.setAttribute('transform', transform);
    this._layout(at[0] + NEEDS_RIGHT > width ? -1 : 1);  // keep the bar and its texts on the map
    const shown = [this.fields.items, this.fields.level, this.fields.capacity, this.fields.x, this.fields.y, this.kind === 'in' ? 'iFr' : null];
    this.forced.setAttribute('visibility', anyForced(live, shown.map((field) => field && tags[field])) ? 'visible' : 'hidden');
    const quality = live.get(tags[this.fields.level] || tags[this.fields.items]);
    const bad = Boolean(quality && quality.q === 2);
    this.node.classList.toggle('q-bad', bad);
    this.footprint.classList.toggle('q-bad', bad);
    if (!this.bar) return;
    const items = value(tags[this.fields.items]);
    const capacity = value(tags[this.fields.capacity]);
    let level = value(tags[this.fields.level]);
    if (typeof level !== 'number' && typeof items === 'number' && typeof capacity === 'number' && capacity > 0) level = 100 * items / capacity;
    const bar = this.bar;
    if (typeof level === 'number') {
      const height = (2 * BAR_HALF - 4) * Math.max(0, Math.min(100, level)) / 100;
      bar.fill.setAttribute('height', height.toFixed(1));
      bar.fill.setAttribute('y', (BAR_HALF - 2 - height).toFixed(1));
      bar.fill.dataset.level = level.toFixed(1);
      if (this.kind === 'in') bar.fill.setAttribute('fill', level >= 95 ? '#b3261e' : level >= 80 ? '#d08a00' : '#2e6fd1');
      setText(bar.percent, `${formatNumber(level, 0)}%`);
    }
    if (typeof items === 'number') setText(bar.count, typeof capacity === 'number' ? `${items}/${capacity}` : String(items));
    const rate = this.kind === 'in' ? value(tags.iFr) : undefined;  // items arriving per minute
    if (typeof rate === 'number') setText(bar.rate, `+${formatNumber(rate, rate % 1 ? 1 : 0)}/min`);
  }

  /** Boxes (map units, [left, top, right, bottom]) a robot's label must keep clear of. */
  obstacles() {
    if (!this.at) return [];
    const [X, Y] = this.at;
    const boxes = [[X - HALF - 10, Y - HALF - 10, X + HALF + 10, Y + HALF + 10]];  // the footprint and its goal outlines
    for (const node of this.node.querySelectorAll('text, .bar-track')) {
      if (node.closest('[visibility="hidden"]') || !node.textContent && node.tagName === 'text') continue;
      const box = localBox(node);
      if (box) boxes.push([X + box[0], Y + box[1], X + box[2], Y + box[3]]);
    }
    return boxes;
  }
}

/** A node's box in its group's units (its text measured when the page has laid it out, else estimated). */
function localBox(node) {
  let box = null;
  try { box = node.getBBox(); } catch { box = null; }
  if (box && box.width > 0) return [box.x, box.y, box.x + box.width, box.y + box.height];
  if (node.tagName !== 'text') return null;
  const width = 8.2 * node.textContent.length;  // 13 px bold, before the first layout
  const x = Number(node.getAttribute('x')) || 0, y = Number(node.getAttribute('y')) || 0;
  const anchor = node.getAttribute('text-anchor');
  const left = anchor === 'end' ? x - width : anchor === 'middle' ? x - width / 2 : x;
  return [left, y - 12, left + width, y + 4];
}
