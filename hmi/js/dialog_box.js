// The modal box every HMI dialog opens in (writes, forces, program control, actions, details) and
// its heading with a close button. Its own module: dialogs.js imports ops/forcing.js, which needs it too.

import { el } from './dom.js';

/** A new modal <dialog> with `node`, removed when closed (one at a time: an open one is closed). */
export function showDialog(node, className) {
  for (const open of document.querySelectorAll('dialog.dialog[open]')) open.close();
  // A fresh element each time: a closing dialog's "close" event never reaches the next one's listeners.
  const box = el('dialog', { class: `dialog ${className || ''}` }, node);
  document.body.append(box);
  box.addEventListener('close', () => box.remove(), { once: true });
  box.showModal();
  return box;
}

/** A dialog's <h2>: the title and a × button that calls `onClose`. */
export function dialogHeading(text, onClose) {
  return el('h2', {}, el('span', { text }), el('button', { type: 'button', class: 'close-x', 'aria-label': 'Close', text: '×', onclick: onClose }));
}
