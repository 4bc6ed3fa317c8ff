// Forcing from the HMI (engineers): force, unforce, unforce and restore — each after a confirmation
// that shows the change as "old → new unit" — and the red "F" every forced value carries.
//
// The semantics are the runtime's (softplc/core/forcing.py, CODESYS-like): programs read the forced
// value, their writes and every client's writes do not reach the tag until it is unforced.
// The commands are tags.force / tags.unforce / tags.forces (commands.js); refusals show inline.

import { el, clear, setText } from '../dom.js';
import { formatWithUnit, formatTime, formatExact } from '../format.js';
import { showDialog, dialogHeading } from '../dialog_box.js';
import { tagFacts, valueEntry } from '../value_entry.js';
import { command, isEngineer } from '../commands.js';

/** The red "F" of a forced value (hidden while not forced). */
export function forcedMark(forced) {
  return el('span', { class: 'forced-mark', title: 'forced by an engineer: programs and clients cannot change it', text: 'F', hidden: !forced });
}

/** Show or hide a mark made by forcedMark(). */
export function showForced(mark, forced) {
  if (mark.hidden === Boolean(forced)) mark.hidden = !forced;
}

/** Whether any of the named items is forced now. */
export function anyForced(live, names) {
  for (const name of names) {
    const item = name ? live.get(name) : undefined;
    if (item && item.f) return true;
  }
  return false;
}

/** The forces in effect: [{tag, value, since, by, previous}] (any role may list them). */
export async function listForces() {
  const answer = await command('tags.forces', {});
  if (!answer.ok) throw new Error(answer.error);
  return answer.result;
}

/** The controls a tag's details row gets: Force… for an engineer, Unforce… while it is forced. */
export function forceControls(ctx, meta, reopen) {
  if (!isEngineer(ctx.session) || meta.access === undefined || meta.name.startsWith('_sys.')) return null;
  const force = el('button', { type: 'button', class: 'btn small danger', text: 'Force…', 'data-force': meta.name,
    onclick: () => openForce(ctx, meta).then(reopen) });
  const unforce = el('button', { type: 'button', class: 'btn small secondary', text: 'Unforce…', 'data-unforce': meta.name, hidden: true,
    onclick: () => openUnforce(ctx, meta).then(reopen) });
  const node = el('span', { class: 'force-controls' }, force, unforce);
  node.liveUpdate = (item) => {
    const forced = Boolean(item && item.f);
    unforce.hidden = !forced;
    force.textContent = forced ? 'Force again…' : 'Force…';
  };
  node.liveUpdate(ctx.live.get(meta.name));
  return node;
}

/** Force a tag after a confirmation; resolves true when the runtime accepted the force. */
export function openForce(ctx, meta) {
  return new Promise((resolve) => {
    let accepted = false;
    let box = null;
    const finish = () => { if (box) box.close(); };
    const unit = meta.unit || '';
    const current = () => ctx.live.get(meta.name);
    const mark = forcedMark(false);
    const { facts, watch } = tagFacts(ctx, meta, mark, (item) => showForced(mark, item && item.f));
    const field = valueEntry(ctx, meta, { id: 'force-value', label: 'Force to', group: 'Forced value' });
    const entry = field.entry;
    // Typed JSON for a bool; the text otherwise, parsed by the runtime by the tag's type (as `softplc force` does).
    const readValue = () => {
      const value = field.read();
      return meta.type === 'bool' || meta.type === 'string' || value === null ? value : value.trim();
    };

    const message = el('div', { role: 'alert' });
    const stepValue = el('div', {}, entry);
    const change = el('div', { class: 'change num' });
    const stepConfirm = el('div', { hidden: true }, el('p', { class: 'muted small', text: 'Please confirm the force:' }), change);
    const back = el('button', { type: 'button', class: 'btn secondary', text: 'Back', hidden: true });
    const next = el('button', { type: 'submit', class: 'btn danger', text: 'Review' });
    const cancel = el('button', { type: 'button', class: 'btn secondary', text: 'Cancel', onclick: finish });
    let pending = null;
    const toConfirm = (value) => {
      pending = value;
      const old = current() ? current().v : meta.value;
      change.replaceChildren(el('span', { class: 'old', text: formatWithUnit(old, unit) }), el('span', { class: 'arrow', text: '→' }),
        el('strong', { class: 'new', text: formatExact(value, unit) }), ' ', forcedMark(true));
      clear(message);
      stepValue.hidden = true;
      stepConfirm.hidden = false;
      back.hidden = false;
      next.textContent = 'Confirm force';
      next.dataset.step = 'confirm';
      next.focus();
    };
    const toValue = () => {
      stepValue.hidden = false; stepConfirm.hidden = true; back.hidden = true;
      next.textContent = 'Review'; next.dataset.step = 'value';
    };
    back.addEventListener('click', toValue);

    const form = el('form', { method: 'dialog', novalidate: true });
    form.addEventListener('submit', async (event) => {
      event.preventDefault();
      if (next.dataset.step !== 'confirm') {
        const value = readValue();
        if (value === null || value === '') return;
        toConfirm(value);
        return;
      }
      next.disabled = true;
      clear(message);
      const answer = await command('tags.force', { tag: meta.name, value: pending });
      next.disabled = false;
      if (answer.ok) {
        accepted = true;
        message.append(el('div', { class: 'done', text: `Forced: ${answer.result}.` }));
        next.hidden = true; back.hidden = true; cancel.textContent = 'Close';
      } else {
        message.append(el('div', { class: 'refusal', 'data-status': answer.status, text: `Refused — ${answer.error}` }));
        toValue();
      }
    });
    form.append(
      dialogHeading(`Force ${meta.name}`, finish),
      meta.description ? el('p', { class: 'desc', text: meta.description }) : null,
      el('p', { class: 'warning small', text: 'Forcing pins the value: programs read it, and neither they nor any client can change it until it is unforced. Everyone sees it marked F.' }),
      facts, stepValue, stepConfirm, message,
      el('div', { class: 'actions' }, cancel, back, next),
    );
    box = showDialog(form, 'force-dialog');
    box.addEventListener('close', () => { watch.close(); resolve(accepted); }, { once: true });
    field.focus();
  });
}

/** Unforce a tag (or unforce and restore it) after a confirmation; resolves true when done. */
export function openUnforce(ctx, meta, force) {
  return new Promise((resolve) => {
    let done = false;
    let box = null;
    const finish = () => { if (box) box.close(); };
    const unit = meta.unit || '';
    const message = el('div', { role: 'alert' });
    const about = el('p', { class: 'muted small', text: 'Looking up the force…' });
    const keep = el('div', { class: 'change num' });
    const restore = el('div', { class: 'change num' });
    const choices = el('div', { class: 'unforce-choices' },
      el('label', {}, el('input', { type: 'radio', name: 'how', value: 'keep', checked: true }), ' Unforce: the tag keeps its value until its owner writes it again'), keep,
      el('label', {}, el('input', { type: 'radio', name: 'how', value: 'restore' }), ' Unforce and restore the value it had before the force'), restore);
    const confirm = el('button', { type: 'submit', class: 'btn', text: 'Confirm unforce', disabled: true });
    const cancel = el('button', { type: 'button', class: 'btn secondary', text: 'Cancel', onclick: finish });
    const form = el('form', { method: 'dialog', novalidate: true },
      dialogHeading(`Unforce ${meta.name}`, finish), about, choices, message, el('div', { class: 'actions' }, cancel, confirm));
    const restoring = () => form.querySelector('input[name=how]:checked').value === 'restore';
    choices.addEventListener('change', () => { confirm.textContent = restoring() ? 'Confirm unforce and restore' : 'Confirm unforce'; });
    form.addEventListener('submit', async (event) => {
      event.preventDefault();
      confirm.disabled = true;
      clear(message);
      const answer = await command('tags.unforce', { tag: meta.name, restore: restoring() });
      if (answer.ok) {
        done = true;
        message.append(el('div', { class: 'done', text: `${answer.result}.` }));
        confirm.hidden = true; cancel.textContent = 'Close';
      } else {
        message.append(el('div', { class: 'refusal', 'data-status': answer.status, text: `Refused — ${answer.error}` }));
        confirm.disabled = false;
      }
    });
    box = showDialog(form, 'force-dialog');
    box.addEventListener('close', () => resolve(done), { once: true });
    const describe = (entry) => {
      if (!entry) {
        setText(about, `${meta.name} is not forced now.`);
        return;
      }
      setText(about, `Forced to ${formatExact(entry.value, unit)} since ${formatTime(entry.since)} by ${entry.by}.`);
      keep.replaceChildren(el('span', { class: 'old', text: formatExact(entry.value, unit) }), el('span', { class: 'arrow', text: '→' }), el('strong', { class: 'new', text: `${formatExact(entry.value, unit)}, not forced` }));
      restore.replaceChildren(el('span', { class: 'old', text: formatExact(entry.value, unit) }), el('span', { class: 'arrow', text: '→' }), el('strong', { class: 'new', text: formatExact(entry.previous, unit) }));
      confirm.disabled = false;
    };
    if (force) describe(force);
    else listForces().then((forces) => describe(forces.find((entry) => entry.tag === meta.name)))
      .catch((error) => setText(about, `The forces cannot be listed: ${error.message}`));
  });
}
