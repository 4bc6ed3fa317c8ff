// A trend chart: pens of historized tags drawn by uPlot (pinned in hmi/package.json, served
// under /vendor/), one y axis per unit, the data from the historian through the history.plot
// command (min/max per bucket for long ranges, so a spike never vanishes), and a live tail:
// while the range ends "now", new values come from the live channel and the window slides on
// the runtime clock. Used by the trend page and by the small trend of a tag's details.

import { el, clear } from './dom.js';
import { callWithTime } from './commands.js';
import { noteRuntimeTime, runtimeNow } from './runtime_clock.js';
import { timeLabels, fullTime } from './trend_time.js';

const UPLOT = '/vendor/uplot/dist/uPlot.esm.js';
const UPLOT_CSS = '/vendor/uplot/dist/uPlot.min.css';
export const PALETTE = ['#1f5fbf', '#c2410c', '#15803d', '#7e22ce', '#b91c1c', '#0e7490', '#a16207', '#be185d'];
export const MISSING_LIBRARY = 'The trend library (uPlot) is not installed in this HMI, so no trend can be drawn. '
  + 'Run scripts/bootstrap.sh (it runs npm ci in hmi/) and restart the runtime; a softplc installed with pip ships it '
  + 'only if npm ci had run before the wheel was built.';

let library = null;

/** uPlot, loaded once (with its stylesheet); rejects with MISSING_LIBRARY when it is not installed. */
export function loadUplot() {
  if (!library) {
    if (!document.querySelector(`link[href="${UPLOT_CSS}"]`)) document.head.append(el('link', { rel: 'stylesheet', href: UPLOT_CSS }));
    library = import(UPLOT).then((module) => module.default).catch(() => {
      library = null;
      throw new Error(MISSING_LIBRARY);
    });
  }
  return library;
}

let historizedCache = null;

/**
 * Whether a pen is drawn as steps (each value held until the next) or sloped (straight lines), by
 * how it is recorded: a tag recorded on every change (or past a deadband) kept its stored value
 * until the next one was stored — a setpoint, an integer, a level that jumps when a robot unloads
 * — so it is drawn as steps; only a compressed tag's archive is a straight-line approximation of
 * its curve (swinging door), drawn sloped.
 */
export function drawnStepped(info) {
  return info.interpolation === 'stepped' || !info.compressed;
}

/** The tags with history: Map name → {tag, type, unit, interpolation, compressed, stepped}. */
export async function historized() {
  if (!historizedCache) {
    historizedCache = callWithTime('history.tags').then((answer) => {
      noteRuntimeTime(answer.time);
      return new Map(answer.result.map((info) => [info.tag, { ...info, stepped: drawnStepped(info) }]));
    });
    historizedCache.catch(() => { historizedCache = null; });
  }
  return historizedCache;
}

const HOLD_END = 1e-3;  // s: a value held up to where the data stop ends this much before the gap

/** A value as a number to plot, or null (a gap) for bad quality and what cannot be plotted. */
function plotValue(value, quality) {
  if (quality === 'bad' || quality === 2) return null;
  if (typeof value === 'boolean') return value ? 1 : 0;
  return typeof value === 'number' && Number.isFinite(value) ? value : null;
}

export class TrendChart {
  /** `options`: {height, compact (no legend, small axes)}. Set `onUserRange(start, end)` to hear zoom and pan. */
  constructor(host, ctx, options = {}) {
    this.host = host;
    this.ctx = ctx;
    this.options = options;
    this.pens = [];
    this.start = 0;
    this.end = 0;
    this.follow = false;
    this.plot = null;
    this.samples = [];  // per pen: the recorded values [[time, value or null (no data)], ...] in time order
    this.before = [];   // per pen: the last value at or before the window's start, or null
    this.xs = [];       // what is drawn (uPlot's aligned data, built from the above by _compose)
    this.ys = [];
    this.onUserRange = null;
    this.problems = [];
    this._request = 0;
    this._watch = null;
    this._tick = null;
    this._lostAt = null;  // runtime time the live channel was lost: values held no further
    this._onState = (event) => {
      if (event.detail.state === 'disconnected' && this._lostAt === null) this._lostAt = runtimeNow(this.ctx.session);
    };
    this._onSynced = () => { this._lostAt = null; this._slide(); };
    ctx.live.addEventListener('state', this._onState);
    ctx.live.addEventListener('synced', this._onSynced);
    if (ctx.live.state === 'disconnected') this._lostAt = runtimeNow(ctx.session);
    this._resize = new ResizeObserver(() => this._fit());
    this._resize.observe(host);
    host.addEventListener('wheel', (event) => this._wheel(event), { passive: false });
    host.trendChart = this;  // for debugging and tests: the pens' data behind the drawing
  }

  /** Draw `pens` ({tag, unit, type, interpolation, color}) over [start, end]; `follow`: a live tail to now. */
  async show(pens, start, end, follow) {
    const uPlot = await loadUplot();
    this.uPlot = uPlot;
    this.pens = pens;
    this.follow = follow;
    await this._load(start, end, true);
  }

  /** Fetch [start, end] again (after a zoom or pan, for the detail of the new range). */
  async reload(start, end, follow) {
    this.follow = follow;
    await this._load(start, end, false);
  }

  destroy() {
    this._request += 1;
    this.ctx.live.removeEventListener('state', this._onState);
    this.ctx.live.removeEventListener('synced', this._onSynced);
    this._resize.disconnect();
    clearInterval(this._tick);
    if (this._watch) this._watch.close();
    if (this.plot) this.plot.destroy();
    this.plot = null;
  }

  // -- data ----------------------------------------------------------------------------------

  async _load(start, end, rebuild) {
    const mine = ++this._request;
    const width = Math.max(200, this.host.clientWidth || 600);
    const points = Math.min(4000, Math.max(200, Math.round(width * 1.5)));
    // Per pen: its values in the window, and the last one before it (held, or sloping, into the window).
    const answers = await Promise.all(this.pens.map((pen) => Promise.all([
      callWithTime('history.plot', { tag: pen.tag, start, end, max_points: points }),
      callWithTime('history.read_raw', { tag: pen.tag, start, end: 0, limit: 1 }),  // start > end: backwards from start
    ]).then(([plot, before]) => ({ plot, before }), (error) => ({ error }))));
    if (mine !== this._request) return;
    this.problems = [];
    this.samples = [];
    this.before = [];
    answers.forEach(({ plot, before, error }, index) => {
      if (error) {
        this.problems.push(`${this.pens[index].tag}: ${error.message}`);
        this.samples.push([]);
        this.before.push(null);
        return;
      }
      noteRuntimeTime(plot.time);
      this.samples.push(plot.result.samples.map((sample) => [sample.time, plotValue(sample.value, sample.quality)]));
      const edge = before.result.samples[0];
      this.before.push(edge ? [edge.time, plotValue(edge.value, edge.quality)] : null);
    });
    this.start = start;
    this.end = end;
    this._compose();
    if (rebuild || !this.plot) this._build();
    else this._redraw();
    this._followLive();
  }

  /** Until when the values shown hold: now on the runtime clock (or when the live channel was lost), at most the window's end. */
  _edge() {
    const now = this._lostAt ?? runtimeNow(this.ctx.session);
    return Math.min(this.end, now);
  }

  /**
   * What uPlot draws, from the recorded values: each pen from its value before the window; a
   * value held up to where the data stop (a null: nothing recorded, the runtime stopped, a bad
   * value), then a gap; the last value held to the edge (now, on the live edge); one x array for
   * every pen, undefined where a pen has no point there (bridged), null for its gaps.
   */
  _compose() {
    const edge = this._edge();
    const columns = this.samples.map((samples, index) => {
      const points = [];
      const before = this.before[index];
      if (before && (!samples.length || before[0] < samples[0][0])) points.push(before);
      for (const point of samples) {
        const previous = points[points.length - 1];
        if (point[1] === null && previous && previous[1] !== null && point[0] - HOLD_END > previous[0]) points.push([point[0] - HOLD_END, previous[1]]);
        points.push(point);
      }
      const last = points[points.length - 1];
      if (last && last[1] !== null && edge > last[0]) points.push([edge, last[1]]);
      return points;
    });
    const times = new Set();
    for (const points of columns) for (const [time] of points) times.add(time);
    this.xs = [...times].sort((a, b) => a - b);
    const position = new Map(this.xs.map((time, i) => [time, i]));
    this.ys = columns.map((points) => {
      const column = new Array(this.xs.length).fill(undefined);
      for (const [time, value] of points) column[position.get(time)] = value;
      return column;
    });
    this.host.dataset.points = String(this.xs.length);
  }

  _append(time, values) {
    // values: one per pen (undefined: no new sample of that pen)
    values.forEach((value, i) => {
      if (value === undefined) return;
      const samples = this.samples[i];
      const last = samples.length ? samples[samples.length - 1] : null;
      if (last && time < last[0]) return;
      if (last && time === last[0]) last[1] = value;
      else samples.push([time, value]);
    });
  }

  // -- live tail ------------------------------------------------------------------------------

  _followLive() {
    if (this._watch) { this._watch.close(); this._watch = null; }
    clearInterval(this._tick);
    if (!this.follow) return;
    const tags = this.pens.map((pen) => pen.tag);
    this._watch = this.ctx.live.watch(tags, (names) => {
      let newest = null;
      const byTime = new Map();
      for (const name of names) {
        const item = this.ctx.live.get(name);
        if (!item) continue;
        noteRuntimeTime(item.t);
        if (!byTime.has(item.t)) byTime.set(item.t, new Array(this.pens.length).fill(undefined));
        this.pens.forEach((pen, i) => { if (pen.tag === name) byTime.get(item.t)[i] = plotValue(item.v, item.q); });
        newest = Math.max(newest ?? -Infinity, item.t);
      }
      for (const time of [...byTime.keys()].sort((a, b) => a - b)) this._append(time, byTime.get(time));
      if (newest !== null) this._slide();
    });
    this._tick = setInterval(() => this._slide(), 1000);
  }

  /** Move the window so it ends now (runtime clock), dropping what fell out of it; a paused window only redraws its edge. */
  _slide() {
    if (!this.plot) return;
    if (this.follow) {
      const span = this.end - this.start;
      const newest = Math.max(0, ...this.samples.map((samples) => (samples.length ? samples[samples.length - 1][0] : 0)));
      this.end = Math.max(runtimeNow(this.ctx.session), newest);
      this.start = this.end - span;
      this.samples.forEach((samples, i) => {
        let drop = 0;
        while (drop < samples.length && samples[drop][0] < this.start) drop += 1;
        if (drop) this.before[i] = samples.splice(0, drop).pop();  // the last one before the window holds into it
      });
    }
    this._compose();
    this._redraw();
    this.host.dataset.end = String(Math.round(this.end));
  }

  // -- drawing --------------------------------------------------------------------------------

  _axesAndScales() {
    const units = [];
    for (const pen of this.pens) {
      const key = pen.type === 'bool' ? 'on/off' : (pen.unit || 'value');
      if (!units.includes(key)) units.push(key);
    }
    const compact = this.options.compact;
    const scales = { x: { time: true } };
    // 24-hour times like every other page; ticks at least 80 px apart, so no label touches the next.
    const axes = [{ scale: 'x', stroke: '#5b6776', grid: { stroke: '#e6eaf0' }, ticks: { stroke: '#d5dbe3' }, size: 50,
      space: 80, values: timeLabels }];
    units.forEach((unit, i) => {
      scales[unit] = unit === 'on/off' ? { range: [-0.1, 1.1] } : { auto: true };
      axes.push({
        scale: unit,
        side: i % 2 === 0 ? 3 : 1,
        label: compact ? undefined : unit,
        labelSize: compact ? 0 : 18,
        size: compact ? 44 : 56,
        stroke: '#5b6776',
        grid: { show: i === 0, stroke: '#e6eaf0' },
        ticks: { stroke: '#d5dbe3' },
        splits: unit === 'on/off' ? () => [0, 1] : undefined,
        values: unit === 'on/off' ? (u, splits) => splits.map((v) => (v === 0 ? 'off' : 'on')) : undefined,
      });
    });
    return { scales, axes };
  }

  _build() {
    if (this.plot) this.plot.destroy();
    clear(this.host);
    const uPlot = this.uPlot;
    const { scales, axes } = this._axesAndScales();
    const stepped = uPlot.paths.stepped({ align: 1 });
    const series = [{ label: 'time', value: (u, v) => (v === null || v === undefined ? '—' : fullTime(v)) }, ...this.pens.map((pen, i) => ({
      label: pen.unit ? `${pen.tag} (${pen.unit})` : pen.tag,
      scale: pen.type === 'bool' ? 'on/off' : (pen.unit || 'value'),
      stroke: pen.color || PALETTE[i % PALETTE.length],
      width: 1.75,
      paths: (pen.stepped ?? pen.interpolation === 'stepped') ? stepped : undefined,
      points: { show: false },
      value: (u, v) => (v === null || v === undefined ? '—' : `${Number.isInteger(v) ? v : v.toFixed(Math.abs(v) >= 100 ? 1 : 3)}${pen.unit ? ` ${pen.unit}` : ''}`),
    }))];
    const plot = new uPlot({
      width: Math.max(200, this.host.clientWidth || 600),
      height: this.options.height || 360,
      scales,
      axes,
      series,
      legend: { show: !this.options.compact },
      cursor: { drag: { x: true, y: false, setScale: true } },
      hooks: { setScale: [(u, key) => this._scaled(u, key)] },
    }, [this.xs, ...this.ys], this.host);
    this.plot = plot;
    plot.setScale('x', { min: this.start, max: this.end });
  }

  _redraw() {
    if (!this.plot) return;
    this.plot.setData([this.xs, ...this.ys], false);
    this.plot.setScale('x', { min: this.start, max: this.end });
  }

  _scaled(u, key) {
    // uPlot calls this after it has drawn (not during setScale): a range other than the one
    // this chart set last is the user's (a drag across the chart, the wheel, the buttons).
    if (key !== 'x') return;
    const { min, max } = u.scales.x;
    if (min === null || max === null || !(max > min)) return;
    const tolerance = (this.end - this.start) * 1e-9 + 1e-6;
    if (Math.abs(min - this.start) <= tolerance && Math.abs(max - this.end) <= tolerance) return;
    this.start = min;
    this.end = max;
    this.follow = false;
    if (this.onUserRange) this.onUserRange(min, max);
  }

  /** The mouse wheel zooms around the cursor. */
  _wheel(event) {
    if (!this.plot || this.options.compact) return;
    event.preventDefault();
    const rect = this.plot.over.getBoundingClientRect();
    const share = Math.min(1, Math.max(0, (event.clientX - rect.left) / rect.width));
    this.zoom(event.deltaY < 0 ? 0.75 : 1 / 0.75, share);
  }

  /** Zoom by `factor` (< 1 in) around `share` of the width (0 left .. 1 right). */
  zoom(factor, share = 0.5) {
    if (!this.plot) return;
    const span = this.end - this.start;
    const at = this.start + span * share;
    const next = Math.max(1, span * factor);
    this.plot.setScale('x', { min: at - next * share, max: at + next * (1 - share) });
  }

  /** Pan by `share` of the visible span (negative: back in time). */
  pan(share) {
    if (!this.plot) return;
    const shift = (this.end - this.start) * share;
    this.plot.setScale('x', { min: this.start + shift, max: this.end + shift });
  }

  _fit() {
    if (!this.plot) return;
    const width = Math.max(200, this.host.clientWidth);
    if (Math.abs(width - this.plot.width) > 2) this.plot.setSize({ width, height: this.options.height || 360 });
  }
}
