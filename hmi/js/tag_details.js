// One tag's details: its declaration, its live value (with the red F while forced), a write button
// where the role may write, Force… / Unforce… for an engineer (ops/forcing.js),
// and — when the tag is historized — a small trend of the last hour with a live tail and a link
// to the trend page. Opened from the tags page, the details of a robot or station, the alarms.

import { el, clear, setText } from './dom.js';
import { formatWithUnit, formatRange, formatTime, qualityName } from './format.js';
import { openWrite } from './dialogs.js';
import { dialogHeading } from './dialog_box.js';
import { TrendChart, historized } from './trend_chart.js';
import { runtimeNow } from './runtime_clock.js';
import { forcedMark, showForced, forceControls } from './ops/forcing.js';

const LAST_HOUR = 3600;

export function openTagDetails(ctx, meta) {
  for (const open of document.querySelectorAll('dialog.dialog[open]')) open.close();
  const value = el('span', { class: 'live-value big num' });
  const quality = el('span', { class: 'qual' });
  const stamp = el('span', { class: 'muted small num' });
  const facts = el('dl', { class: 'kv small' },
    el('dt', { text: 'Type' }), el('dd', { text: meta.type }),
    el('dt', { text: 'Access' }), el('dd', { text: meta.access }),
    el('dt', { text: 'Group' }), el('dd', { text: meta.group || '—' }));
  const range = formatRange(meta);
  if (range) facts.append(el('dt', { text: 'Range' }), el('dd', { text: `${range}${meta.unit ? ` ${meta.unit}` : ''}` }));
  const trendArea = el('div', { class: 'mini-trend-area' });
  const forced = forcedMark(meta.forced);
  const reopen = () => openTagDetails(ctx, meta);
  const write = meta.writable && ctx.session.role !== 'viewer'
    ? el('button', { type: 'button', class: 'btn small secondary', text: 'Write…', onclick: () => openWrite(ctx, meta).then(reopen) })
    : null;
  const force = forceControls(ctx, meta, reopen);
  const box = el('dialog', { class: 'dialog drawer tag-details', 'data-tag': meta.name },
    el('div', { class: 'body' },
      dialogHeading(meta.name, () => box.close()),
      meta.description ? el('p', { class: 'desc', text: meta.description }) : null,
      el('div', { class: 'tag-now' }, value, forced, quality, stamp, write, force),
      facts, trendArea));
  document.body.append(box);

  const paint = () => {
    const item = ctx.live.get(meta.name);
    setText(value, formatWithUnit(item ? item.v : meta.value, meta.unit));
    const code = item ? item.q : ({ good: 0, uncertain: 1, bad: 2 }[meta.quality] ?? 0);
    setText(quality, qualityName(code));
    quality.className = `qual ${qualityName(code)}`;
    setText(stamp, formatTime(item ? item.t : meta.timestamp));
    showForced(forced, item ? item.f : meta.forced);
    if (force && force.liveUpdate) force.liveUpdate(item);
  };
  const watch = ctx.live.watch([meta.name], paint);
  paint();

  let chart = null;
  const hasTrends = (ctx.session.pages || []).some((page) => page.id === 'trends');
  if (hasTrends && meta.type !== 'string') {
    historized().then(async (known) => {
      const info = known.get(meta.name);
      if (!info || !box.isConnected) return;
      const host = el('div', { class: 'mini-trend', id: 'mini-trend' });
      clear(trendArea).append(
        el('div', { class: 'mini-trend-head' }, el('span', { class: 'small muted', text: 'Last hour' }),
          el('a', { href: `#/trends?tags=${encodeURIComponent(meta.name)}&range=1h`, class: 'small', text: 'Open in Trends →', onclick: () => box.close() })),
        host);
      chart = new TrendChart(host, ctx, { height: 150, compact: true });
      const end = runtimeNow(ctx.session);
      try {
        await chart.show([{ ...info, color: '#1f5fbf' }], end - LAST_HOUR, end, true);
      } catch (error) {
        clear(host).append(el('p', { class: 'muted small', text: error.message }));
      }
    }).catch(() => { /* no history: no trend */ });
  }
  box.addEventListener('close', () => {
    watch.close();
    if (chart) chart.destroy();
    box.remove();
  }, { once: true });
  box.showModal();
  return box;
}
