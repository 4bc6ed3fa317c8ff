// A user mimic: the engineer's SVG with its elements bound to tags (hmi: views: in tagdb.yaml).
// Expressions are evaluated on the server; the page only shows values (docs/hmi.md, "Views").

import { el, svg, setText } from '../dom.js';
import { anyForced } from '../ops/forcing.js';
import { get, tagMeta } from '../api.js';
import { parseSvg } from '../svg.js';
import { formatValue } from '../format.js';

export async function mount(root, ctx) {
  const name = ctx.params.view;
  const view = await get(`/api/views/${encodeURIComponent(name)}`);
  const response = await fetch(view.svg, { credentials: 'same-origin' });
  if (!response.ok) throw new Error(`the drawing of view ${name} could not be loaded (${response.status})`);
  const drawing = parseSvg(await response.text());
  drawing.classList.add('mimic-live');
  const host = el('div', { class: 'mimic-host' }, drawing);
  root.append(el('div', { class: 'panel-head' }, el('h1', { text: view.title })), host);

  const metas = new Map((await tagMeta(view.items)).map((meta) => [meta.name, meta]));
  const byItem = new Map();  // item → bindings
  const transforms = new Map();  // element → {base, translate, rotate}
  for (const binding of view.bindings) {
    const element = findById(drawing, binding.id);
    if (!element) continue;
    binding.element = element;
    if (binding.kind === 'bar') {
      binding.box = ['x', 'y', 'width', 'height'].map((key) => parseFloat(element.getAttribute(key)) || 0);
    }
    if (binding.kind === 'translate' || binding.kind === 'rotate') {
      if (!transforms.has(element)) transforms.set(element, { base: element.getAttribute('transform') || '', translate: '', rotate: '' });
    }
    if (binding.kind === 'text') binding.target = element.querySelector('tspan') || element;
    if (binding.kind === 'click') {
      element.classList.add('mimic-clickable');
      element.setAttribute('tabindex', '0');
      element.setAttribute('role', 'button');
      const act = () => click(ctx, binding, metas);
      element.addEventListener('click', act);
      element.addEventListener('keydown', (event) => { if (event.key === 'Enter') act(); });
      continue;
    }
    for (const item of [binding.source, binding.x, binding.y]) {
      if (!item) continue;
      if (!byItem.has(item)) byItem.set(item, []);
      byItem.get(item).push(binding);
    }
  }

  // A red "F" on every element drawn from a forced tag (expressions are never forced themselves).
  const ofElement = new Map();  // element → its bindings
  for (const binding of view.bindings) {
    if (!binding.element || binding.kind === 'click') continue;
    if (!ofElement.has(binding.element)) ofElement.set(binding.element, []);
    ofElement.get(binding.element).push(binding);
  }
  const badges = new Map();  // element → its badge (made when it is first forced)
  const markForced = (element) => {
    const items = (ofElement.get(element) || []).flatMap((binding) => [binding.source, binding.x, binding.y]);
    const forced = anyForced(ctx.live, items.filter((item) => item && !item.startsWith('=')));
    let badge = badges.get(element);
    if (!badge && !forced) return;
    if (!badge) badges.set(element, (badge = forcedBadge(element)));
    badge.setAttribute('visibility', forced ? 'visible' : 'hidden');
    if (badge.parentNode !== element) badge.setAttribute('transform', element.getAttribute('transform') || '');  // follows a moving element
    element.classList.toggle('hmi-forced', forced);
  };

  const live = ctx.live;
  const value = (item) => { const entry = item ? live.get(item) : undefined; return entry ? entry.v : undefined; };
  const qualityOf = (item) => { const entry = item ? live.get(item) : undefined; return entry ? entry.q : 0; };
  const apply = (binding) => {
    const quality = Math.max(qualityOf(binding.source), qualityOf(binding.x), qualityOf(binding.y));
    const element = binding.element;
    const v = value(binding.source);
    switch (binding.kind) {
      case 'text': {
        let text;
        if (binding.map && v !== undefined && binding.map[String(v)] !== undefined) text = binding.map[String(v)];
        else text = formatValue(v, metas.get(binding.source), binding.decimals);
        setText(binding.target, binding.unit && v !== undefined && !binding.map ? `${text} ${binding.unit}` : text);
        break;
      }
      case 'fill':
      case 'stroke': {
        let colour;
        if (binding.thresholds) {
          for (const [from, c] of binding.thresholds) if (typeof v === 'number' && v >= from) colour = c;
          if (colour === undefined && binding.thresholds.length) colour = binding.thresholds[0][1];
        } else colour = v ? binding.on_color : binding.off_color;
        if (colour) element.style[binding.kind] = colour;
        break;
      }
      case 'visible':
        element.style.display = v ? '' : 'none';
        break;
      case 'bar': {
        const [x, y, width, height] = binding.box;
        const share = typeof v === 'number' ? Math.max(0, Math.min(1, (v - binding.min) / (binding.max - binding.min))) : 0;
        if (binding.direction === 'up') { element.setAttribute('height', height * share); element.setAttribute('y', y + height * (1 - share)); }
        else if (binding.direction === 'down') element.setAttribute('height', height * share);
        else if (binding.direction === 'right') element.setAttribute('width', width * share);
        else { element.setAttribute('width', width * share); element.setAttribute('x', x + width * (1 - share)); }
        element.dataset.share = share.toFixed(4);
        break;
      }
      case 'translate': {
        const state = transforms.get(element);
        const tx = binding.offset[0] + (binding.x && typeof value(binding.x) === 'number' ? binding.scale[0] * value(binding.x) : 0);
        const ty = binding.offset[1] + (binding.y && typeof value(binding.y) === 'number' ? binding.scale[1] * value(binding.y) : 0);
        state.translate = `translate(${tx.toFixed(2)} ${ty.toFixed(2)})`;
        element.setAttribute('transform', `${state.translate} ${state.base} ${state.rotate}`.trim());
        break;
      }
      case 'rotate': {
        const state = transforms.get(element);
        const angle = binding.offset + binding.scale * (typeof v === 'number' ? v : 0);
        state.rotate = binding.center ? `rotate(${angle.toFixed(2)} ${binding.center[0]} ${binding.center[1]})` : `rotate(${angle.toFixed(2)})`;
        element.setAttribute('transform', `${state.translate} ${state.base} ${state.rotate}`.trim());
        break;
      }
      default:
        break;
    }
    markForced(element);
    if (quality !== (binding.quality || 0)) {  // most updates keep the quality: touch classes only on a change
      binding.quality = quality;
      element.classList.toggle('hmi-q-uncertain', quality === 1);
      element.classList.toggle('hmi-q-bad', quality === 2);
      if (binding.target && binding.target !== element) binding.target.classList.toggle('hmi-q-bad', quality === 2);
    }
  };

  const update = (items) => {
    const done = new Set();
    for (const item of items) {
      for (const binding of byItem.get(item) || []) {
        if (done.has(binding)) continue;
        done.add(binding);
        apply(binding);
      }
    }
  };
  const watch = ctx.live.watch([...byItem.keys()], update);
  update([...byItem.keys()]);
  const ready = () => { root.dataset.ready = '1'; };
  if (ctx.live.synced) ready();
  ctx.live.addEventListener('synced', ready);
  return () => { watch.close(); ctx.live.removeEventListener('synced', ready); };
}

function forcedBadge(element) {
  let box = { x: 0, y: 0, width: 0 };
  try { box = element.getBBox(); } catch { /* not rendered (hidden): at its origin */ }
  const mark = svg('g', { class: 'forced-badge', 'data-forced-for': element.id, transform: `translate(${(box.x + box.width - 7).toFixed(1)} ${(box.y - 8).toFixed(1)})` },
    svg('rect', { width: 14, height: 15, rx: 3 }), svg('text', { x: 7, y: 11.5, 'text-anchor': 'middle', text: 'F' }));
  if (element.localName === 'g') {
    element.append(mark);
    return mark;
  }
  const holder = svg('g', { class: 'forced-holder' }, mark);  // beside the element, in its coordinates
  element.after(holder);
  return holder;
}

function findById(drawing, id) {
  for (const node of drawing.querySelectorAll('[id]')) if (node.id === id) return node;
  return null;
}

async function click(ctx, binding, metas) {
  const name = binding.dialog || binding.tag;
  let meta = metas.get(name);
  if (!meta) [meta] = await tagMeta([name]);
  if (!meta) return;
  if (!meta.writable) {
    ctx.openDetails(`${name}`, [meta], `You may not write ${name} (${ctx.session.role || 'visitor'}).`);
    return;
  }
  if (binding.dialog) ctx.openWrite(meta);
  else ctx.openWrite(meta, binding.write);
}
