// Trends: several pens of historized tags with their units (an axis per unit), a time range
// (last 10 min … 7 d, or from … to), zoom (drag across the chart, the wheel, + / −) and pan
// (◀ ▶), and a live tail while the range ends now. Drawn by uPlot (trend_chart.js); the page
// says so plainly when that library is not installed. `#/trends?tags=a,b&range=1h`.

import { el, clear, setText } from '../dom.js';
import { TrendChart, PALETTE, historized, loadUplot } from '../trend_chart.js';
import { runtimeNow } from '../runtime_clock.js';

const RANGES = [['10m', '10 min', 600], ['1h', '1 h', 3600], ['8h', '8 h', 28800], ['1d', '1 d', 86400], ['7d', '7 d', 604800]];
const MAX_PENS = 8;
const PENS_KEY = 'softplc.trendPens';

function localInput(seconds) {
  const date = new Date(seconds * 1000);
  const pad = (n) => String(n).padStart(2, '0');
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())}T${pad(date.getHours())}:${pad(date.getMinutes())}:${pad(date.getSeconds())}`;
}

/**
 * The pens of a first visit: what an operator of the plant watches — the recorded levels (unit %:
 * the tasks' input buffers `*_iBL` first, then their output storages `*_qSL`, then other levels),
 * else the first recorded numbers.
 */
export function defaultPens(plottable) {
  const levels = plottable.filter((info) => info.unit === '%' && !info.type.startsWith('bool'));
  if (levels.length) {
    const rank = (info) => (/_iBL$/.test(info.tag) ? 0 : /_qSL$/.test(info.tag) ? 1 : 2);
    return [...levels].sort((a, b) => rank(a) - rank(b)).slice(0, 4).map((info) => info.tag);  // a stable sort: names in order
  }
  const numbers = plottable.filter((info) => info.type.startsWith('float'));
  return (numbers.length ? numbers : plottable).slice(0, 2).map((info) => info.tag);
}

function rememberedPens() {
  try { return (localStorage.getItem(PENS_KEY) || '').split(',').filter(Boolean); } catch { return []; }
}

export async function mount(root, ctx) {
  const problem = el('div', { role: 'alert', class: 'trend-problems' });
  const host = el('div', { class: 'trend-host', id: 'trend-chart' });
  const penList = el('div', { class: 'pens', 'aria-label': 'Pens' });
  const picker = el('input', { type: 'text', id: 'trend-tag', list: 'trend-tags', placeholder: 'Add a pen: tag name…', 'aria-label': 'Tag to add', autocomplete: 'off' });
  const options = el('datalist', { id: 'trend-tags' });
  const add = el('button', { type: 'submit', class: 'btn small', text: 'Add pen' });
  const rangeButtons = RANGES.map(([key, label]) => el('button', { type: 'button', class: 'btn small secondary range', 'data-range': key, text: label }));
  const customButton = el('button', { type: 'button', class: 'btn small secondary range', 'data-range': 'custom', text: 'From … to…' });
  const from = el('input', { type: 'datetime-local', step: 1, id: 'trend-from', 'aria-label': 'From' });
  const to = el('input', { type: 'datetime-local', step: 1, id: 'trend-to', 'aria-label': 'To' });
  const applyCustom = el('button', { type: 'button', class: 'btn small', text: 'Show' });
  const custom = el('div', { class: 'custom-range', hidden: true }, from, to, applyCustom);
  const live = el('span', { class: 'chip', id: 'trend-live' });
  const backToLive = el('button', { type: 'button', class: 'btn small', text: 'Back to live', hidden: true });
  const nav = (label, title, action) => el('button', { type: 'button', class: 'btn small secondary', title, 'aria-label': title, text: label, onclick: action });
  root.append(el('section', { class: 'panel trends-page' },
    el('div', { class: 'panel-head' }, el('h1', { text: 'Trends' }), el('span', { class: 'live-area' }, live, backToLive)),
    el('form', { class: 'toolbar pen-form' }, picker, options, add),
    penList,
    el('div', { class: 'toolbar range-bar' }, el('span', { class: 'muted small', text: 'Last' }), ...rangeButtons, customButton, custom,
      el('span', { class: 'zoom-buttons' },
        nav('◀', 'Back in time', () => chart && chart.pan(-0.5)), nav('▶', 'Forward in time', () => chart && chart.pan(0.5)),
        nav('+', 'Zoom in', () => chart && chart.zoom(0.5)), nav('−', 'Zoom out', () => chart && chart.zoom(2)))),
    problem, host,
    el('p', { class: 'muted small hint', text: 'Drag across the chart to zoom into a time span; the mouse wheel zooms too. Values come from the historian, decimated to the chart\'s width (every spike is kept).' })));

  let chart = null;
  const fail = (text) => { clear(problem); if (text) problem.append(el('div', { class: 'error-banner', id: 'trend-missing', text })); };
  try {
    await loadUplot();
  } catch (error) {
    fail(error.message);
    root.dataset.ready = '1';
    return () => {};
  }
  let known;
  try {
    known = await historized();
  } catch (error) {
    fail(`The history cannot be read: ${error.message}`);
    root.dataset.ready = '1';
    return () => {};
  }
  const plottable = [...known.values()].filter((info) => info.type !== 'string');
  for (const info of plottable) options.append(el('option', { value: info.tag, text: info.unit ? `${info.tag} (${info.unit})` : info.tag }));
  if (!plottable.length) {
    fail('No tag has history: the historian records the tags of the history: section (docs/history.md).');
    root.dataset.ready = '1';
    return () => {};
  }

  const wanted = (ctx.params.tags ? ctx.params.tags.split(',') : rememberedPens()).filter((tag) => known.has(tag) && known.get(tag).type !== 'string');
  let pens = (wanted.length ? wanted : defaultPens(plottable)).slice(0, MAX_PENS).map((tag, i) => ({ ...known.get(tag), color: PALETTE[i % PALETTE.length] }));
  let range = RANGES.some(([key]) => key === ctx.params.range) || ctx.params.range === 'custom' ? ctx.params.range : '10m';
  if (range === 'custom') {
    from.value = ctx.params.from ? localInput(Number(ctx.params.from)) : '';
    to.value = ctx.params.to ? localInput(Number(ctx.params.to)) : '';
  }
  let following = false;

  const remember = () => {
    const query = new URLSearchParams({ tags: pens.map((pen) => pen.tag).join(','), range });
    if (range === 'custom') { query.set('from', String(Math.round(new Date(from.value).getTime() / 1000))); query.set('to', String(Math.round(new Date(to.value).getTime() / 1000))); }
    history.replaceState(null, '', `#/trends?${query}`);
    try { localStorage.setItem(PENS_KEY, pens.map((pen) => pen.tag).join(',')); } catch { /* private mode */ }
  };
  const showLive = () => {
    const cut = following && document.body.classList.contains('offline');  // the runtime is unreachable (main.js)
    live.className = `chip ${cut ? 'bad' : following ? 'ok' : 'idle'}`;
    setText(live, cut ? 'not live' : following ? 'live' : 'paused');
    live.title = cut ? 'The runtime cannot be reached: the values end where it was lost'
      : following ? 'New values are appended as they come' : 'Not following: the range does not end now';
    backToLive.hidden = following;
    for (const button of [...rangeButtons, customButton]) button.setAttribute('aria-pressed', button.dataset.range === range ? 'true' : 'false');
    custom.hidden = range !== 'custom';
  };
  const renderPens = () => {
    clear(penList);
    for (const pen of pens) {
      penList.append(el('span', { class: 'pen', 'data-pen': pen.tag },
        el('span', { class: `swatch c${PALETTE.indexOf(pen.color)}`, 'aria-hidden': 'true' }),
        el('span', { class: 'pen-name', text: pen.tag }),
        pen.unit ? el('span', { class: 'muted small', text: pen.unit }) : null,
        el('button', { type: 'button', class: 'close-x', 'aria-label': `Remove ${pen.tag}`, text: '×', onclick: () => {
          pens = pens.filter((other) => other !== pen);
          draw(true);
        } })));
    }
  };

  function window_() {
    if (range === 'custom') {
      const start = new Date(from.value).getTime() / 1000;
      const end = new Date(to.value).getTime() / 1000;
      return Number.isFinite(start) && Number.isFinite(end) && end > start ? [start, end, false] : null;
    }
    const span = RANGES.find(([key]) => key === range)[2];
    const end = runtimeNow(ctx.session);
    return [end - span, end, true];
  }

  async function draw(rebuild) {
    renderPens();
    remember();
    const chosen = window_();
    if (!chosen) { fail('Choose a start before the end.'); return; }
    fail('');
    const [start, end, follow] = chosen;
    following = follow;
    showLive();
    if (!pens.length) {
      if (chart) chart.destroy();
      chart = null;
      clear(host);
      host.append(el('p', { class: 'muted empty-chart', text: 'Add a pen to draw a trend.' }));
      return;
    }
    if (!chart || rebuild) {
      if (chart) chart.destroy();
      chart = new TrendChart(host, ctx, { height: Math.max(260, Math.min(520, window.innerHeight - 320)) });
      chart.onUserRange = (userStart, userEnd) => {
        following = false;
        showLive();
        clearTimeout(refetch);
        refetch = setTimeout(() => chart && chart.reload(userStart, userEnd, false).then(report), 250);
      };
      await chart.show(pens, start, end, follow);
    } else {
      await chart.reload(start, end, follow);
    }
    report();
  }
  let refetch = null;
  const report = () => {
    if (chart && chart.problems.length) fail(chart.problems.join('\n'));
    host.dataset.pens = pens.map((pen) => pen.tag).join(',');
  };

  for (const button of rangeButtons) button.addEventListener('click', () => { range = button.dataset.range; draw(false); });
  customButton.addEventListener('click', () => {
    const [start, end] = window_() || [runtimeNow(ctx.session) - 3600, runtimeNow(ctx.session)];
    range = 'custom';
    from.value = localInput(chart ? chart.start : start);
    to.value = localInput(chart ? chart.end : end);
    showLive();
  });
  applyCustom.addEventListener('click', () => draw(false));
  backToLive.addEventListener('click', () => { if (range === 'custom') range = '10m'; draw(false); });
  picker.form.addEventListener('submit', (event) => {
    event.preventDefault();
    const tag = picker.value.trim();
    const info = known.get(tag);
    if (!info || info.type === 'string') { fail(`${tag || 'That'} has no plottable history (see the list of tags with history).`); return; }
    if (pens.some((pen) => pen.tag === tag)) { picker.value = ''; return; }
    if (pens.length >= MAX_PENS) { fail(`At most ${MAX_PENS} pens.`); return; }
    const used = new Set(pens.map((pen) => pen.color));
    pens = [...pens, { ...info, color: PALETTE.find((color) => !used.has(color)) || PALETTE[0] }];
    picker.value = '';
    draw(true);
  });

  await draw(true);
  ctx.live.addEventListener('state', showLive);
  ctx.live.addEventListener('synced', showLive);
  root.dataset.ready = '1';
  return () => {
    clearTimeout(refetch);
    ctx.live.removeEventListener('state', showLive);
    ctx.live.removeEventListener('synced', showLive);
    if (chart) chart.destroy();
  };
}
