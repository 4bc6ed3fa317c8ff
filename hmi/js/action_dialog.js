// A small modal form for an operator's action (shelve with a reason, comment, acknowledge all):
// fields, one submit button, the runtime's answer or refusal shown in the dialog itself.

import { el, clear } from './dom.js';
import { showDialog, dialogHeading } from './dialog_box.js';

/**
 * Open a form. `build(form)` returns {body: [nodes], read(): args or a string saying what is missing};
 * `submit(args)` performs the action and resolves to the text to show (or throws with the refusal).
 * Resolves true when the action was carried out.
 */
export function openActionDialog({ title, intro, submitLabel, build, submit }) {
  return new Promise((resolve) => {
    let done = false;
    let box = null;
    const message = el('div', { role: 'alert' });
    const go = el('button', { type: 'submit', class: 'btn', text: submitLabel });
    const cancel = el('button', { type: 'button', class: 'btn secondary', text: 'Cancel' });
    const form = el('form', { method: 'dialog', novalidate: true });
    const parts = build(form);
    form.append(
      dialogHeading(title, () => box.close()),
      intro ? el('p', { class: 'desc', text: intro }) : null,
      ...parts.body, message,
      el('div', { class: 'actions' }, cancel, go),
    );
    cancel.addEventListener('click', () => box.close());
    form.addEventListener('submit', async (event) => {
      event.preventDefault();
      clear(message);
      const args = parts.read();
      if (typeof args === 'string') {
        message.append(el('div', { class: 'refusal', text: args }));
        return;
      }
      go.disabled = true;
      try {
        const text = await submit(args);
        done = true;
        message.append(el('div', { class: 'done', text: text || 'Done.' }));
        go.hidden = true;
        cancel.textContent = 'Close';
        setTimeout(() => box.close(), 1200);
      } catch (error) {
        message.append(el('div', { class: 'refusal', text: `Refused — ${error.message}` }));
      } finally {
        go.disabled = false;
      }
    });
    box = showDialog(form, 'action-dialog');
    box.addEventListener('close', () => resolve(done), { once: true });
    const first = form.querySelector('input, textarea, select');
    if (first) first.focus();
  });
}
