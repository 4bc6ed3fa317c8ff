// The banner under the header on every page, for everyone, while any tag is forced: forcing a
// live plant must be impossible to miss. "3 tags forced: t01_iFr = 0, ... — the Forced list".
//
// It follows `_sys.forced` (the count) and the forced tags themselves, and asks for the list
// (tags.forces) whenever either says something changed.

import { el, setText } from '../dom.js';
import { formatValue } from '../format.js';
import { listForces } from './forcing.js';

const SHOWN = 4;  // tags named in the banner; the Forced page lists them all

export function mount(node, ctx) {
  node.className = 'forced-banner';
  node.setAttribute('role', 'status');
  node.hidden = true;
  const text = el('span', { class: 'forced-text' });
  const link = el('a', { href: '#/forced', text: 'Forced list →' });
  node.append(el('strong', { class: 'forced-icon', 'aria-hidden': 'true', text: 'F' }), text, link);

  let listed = [];
  let asking = null;
  let again = false;
  const watch = ctx.live.watch(['_sys.forced'], (names) => {
    const count = ctx.live.get('_sys.forced');
    const gone = listed.some((name) => { const item = ctx.live.get(name); return names.includes(name) && item && !item.f; });
    if (names.includes('_sys.forced') || gone) refresh(count ? count.v : 0);
  });
  const refresh = (count) => {
    if (!count) {
      show([]);
      return;
    }
    if (asking) { again = true; return; }
    asking = listForces().then(show).catch(() => {
      setText(text, `${count} tag${count === 1 ? '' : 's'} forced`);
      node.hidden = false;
    }).finally(() => {
      asking = null;
      if (again) { again = false; const now = ctx.live.get('_sys.forced'); refresh(now ? now.v : 0); }
    });
  };
  const show = (forces) => {
    listed = forces.map((force) => force.tag);
    watch.update(['_sys.forced', ...listed]);
    node.hidden = forces.length === 0;
    node.dataset.count = String(forces.length);
    if (!forces.length) return;
    const named = forces.slice(0, SHOWN).map((force) => `${force.tag} = ${typeof force.value === 'number' ? String(force.value) : formatValue(force.value)}`).join(', ');
    const more = forces.length > SHOWN ? ` and ${forces.length - SHOWN} more` : '';
    setText(text, `${forces.length} tag${forces.length === 1 ? '' : 's'} forced: ${named}${more}. Programs and clients cannot change ${forces.length === 1 ? 'it' : 'them'}.`);
  };
  return () => watch.close();
}
