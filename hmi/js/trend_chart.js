// A trend chart: pens of historized tags drawn by uPlot (pinned in hmi/package.json, served
// under /vendor/), one y axis per unit, the data from the historian through the history.plot
// command (min/max per bucket for long ranges, so a spike never vanishes), and a live tail:
// while the range ends "now", new values come from the live channel and the window slides on
// the runtime clock. Used by the trend page and by the small trend of a tag's details.

import { el, clear } from './dom.js';
import { callWithTime } from './commands.js';
import { noteRuntimeTime, runtimeNow } from './runtime_clock.js';

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

/** The tags with history: Map name → {tag, type, unit, interpolation}. */
export async function historized() {
  if (!historizedCache) {
    historizedCache = callWithTime('history.tags').then((answer) => {
      noteRuntimeTime(answer.time);
      return new Map(answer.result.map((info) => [info.tag, info]));
    });
    historizedCache.catch(() => { historizedCache = null; });
  }
  return historizedCache;
}

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
    this.xs = [];
    this.ys = [];
    this.onUserRange = null;
    this.problems = [];
    this._request = 0;
    this._watch = null;
    this._tick = null;
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
    const answers = await Promise.all(this.pens.map((pen) => callWithTime('history.plot', { tag: pen.tag, start, end, max_points: points })
      .then((answer) => ({ answer }), (error) => ({ error }))));
    if (mine !== this._request) return;
    this.problems = [];
    const series = answers.map(({ answer, error }, index) => {
      if (error) {
        this.problems.push(`${this.pens[index].tag}: ${error.message}`);
        return [];
      }
      noteRuntimeTime(answer.time);
      return answer.result.samples.map((sample) => [sample.time, plotValue(sample.value, sample.quality)]);
    });
    this._merge(series);
    this.start = start;
    this.end = end;
    if (rebuild || !this.plot) this._build();
    else this._redraw();
    this._followLive();
    this.host.dataset.points = String(this.xs.length);
  }

  /** One x array for every pen (uPlot's aligned data): undefined where a pen has no sample (bridged), null for its gaps. */
  _merge(series) {
    const times = new Set();
    for (const samples of series) for (const [time] of samples) times.add(time);
    this.xs = [...times].sort((a, b) => a - b);
    const index = new Map(this.xs.map((time, i) => [time, i]));
    this.ys = series.map((samples) => {
      const column = new Array(this.xs.length).fill(undefined);
      for (const [time, value] of samples) column[index.get(time)] = value;
      return column;
    });
  }

  _append(time, values) {
    // values: one per pen (undefined: no new sample of that pen)
    const last = this.xs.length ? this.xs[this.xs.length - 1] : -Infinity;
    if (time < last) return;
    if (time === last) {
      values.forEach((value, i) => { if (value !== undefined) this.ys[i][this.xs.length - 1] = value; });
      return;
    }
    this.xs.push(time);
    values.forEach((value, i) => this.ys[i].push(value));
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

  /** Move the window so it ends now (runtime clock), dropping what fell out of it. */
  _slide() {
    if (!this.follow || !this.plot) return;
    const span = this.end - this.start;
    const now = Math.max(runtimeNow(this.ctx.session), this.xs.length ? this.xs[this.xs.length - 1] : 0);
    this.end = now;
    this.start = now - span;
    let drop = 0;
    while (drop < this.xs.length - 2 && this.xs[drop + 1] < this.start) drop += 1;  // keep one point before the window
    if (drop) {
      this.xs.splice(0, drop);
      for (const column of this.ys) column.splice(0, drop);
    }
    this._redraw();
    this.host.dataset.points = String(this.xs.length);
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
    const axes = [{ scale: 'x', stroke: '#5b6776', grid: { stroke: '#e6eaf0' }, ticks: { stroke: '#d5dbe3' }, size: compact ? 30 : 42 }];
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
    const series = [{ label: 'time' }, ...this.pens.map((pen, i) => ({
      label: pen.unit ? `${pen.tag} (${pen.unit})` : pen.tag,
      scale: pen.type === 'bool' ? 'on/off' : (pen.unit || 'value'),
      stroke: pen.color || PALETTE[i % PALETTE.length],
      width: 1.75,
      paths: pen.interpolation === 'stepped' ? stepped : undefined,
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
