// What a dialog that changes one tag (write, force) shows and asks: the tag's facts (its live
// value, type and range) and a field for the new value — radio buttons for a bool, text otherwise.

import { el, setText } from './dom.js';
import { formatWithUnit, formatRange, qualityName } from './format.js';

/**
 * The tag's facts as a <dl>: Now (live value and quality, then `mark` if given), Type, Range.
 * `onItem(item)` runs at every change too. Returns {facts, watch}: close `watch` with the dialog.
 */
export function tagFacts(ctx, meta, mark, onItem) {
  const unit = meta.unit || '';
  const now = el('span', { class: 'live-value num' });
  const show = () => {
    const item = ctx.live.get(meta.name);
    setText(now, item ? `${formatWithUnit(item.v, unit)} (${qualityName(item.q)})` : formatWithUnit(meta.value, unit));
    if (onItem) onItem(item);
  };
  const watch = ctx.live.watch([meta.name], show);
  show();
  const facts = el('dl', { class: 'kv small' },
    el('dt', { text: 'Now' }), mark ? el('dd', {}, now, ' ', mark) : el('dd', {}, now),
    el('dt', { text: 'Type' }), el('dd', { text: meta.type }));
  const range = formatRange(meta);
  if (range) facts.append(el('dt', { text: 'Range' }), el('dd', { text: `${range}${unit ? ` ${unit}` : ''}` }));
  return { facts, watch };
}

/**
 * A field for the tag's new value, filled from its value now (a bool offers the other value).
 * `label` heads it, `group` names a bool's radio group, `id` is the text field's id.
 * Returns {entry, read(), focus()}: read() is the chosen bool (null: none) or the field's text.
 */
export function valueEntry(ctx, meta, { id, label, group }) {
  const unit = meta.unit || '';
  const item = ctx.live.get(meta.name);
  const now = item ? item.v : meta.value;
  const entry = el('div');
  let input;
  if (meta.type === 'bool') {
    const make = (choice) => el('label', {}, el('input', { type: 'radio', name: 'value', value: String(choice), checked: choice === !now }), choice ? 'true' : 'false');
    input = el('div', { class: 'choices', role: 'radiogroup', 'aria-label': group || label }, make(true), make(false));
    entry.append(el('label', { text: label }), input);
  } else {
    input = el('input', { type: 'text', name: 'value', autocomplete: 'off', inputmode: meta.type === 'string' ? 'text' : 'decimal', id });
    input.value = now === undefined || now === null ? '' : String(now);
    entry.append(el('label', { for: id, text: `${label}${unit ? ` (${unit})` : ''}` }), input);
  }
  const read = () => {
    if (meta.type !== 'bool') return input.value;
    const checked = input.querySelector('input:checked');
    return checked ? checked.value === 'true' : null;
  };
  const focus = () => (meta.type === 'bool' ? input.querySelector('input') : input).focus();
  return { entry, read, focus };
}
