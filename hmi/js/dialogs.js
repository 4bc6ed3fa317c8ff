// Dialogs: writing a tag (value → confirmation "old → new unit" → result or the refusal's
// rule), logging in, and the live details of a robot, a task or any set of tags.

import { el, clear, setText } from './dom.js';
import { writeTag, post } from './api.js';
import { formatValue, formatWithUnit, formatExact, qualityName } from './format.js';
import { showDialog, dialogHeading } from './dialog_box.js';
import { tagFacts, valueEntry } from './value_entry.js';
import { forcedMark, showForced, forceControls } from './ops/forcing.js';

function parseInput(meta, text) {
  if (meta.type === 'string') return text;
  const trimmed = text.trim();
  const number = Number(trimmed);
  // Not a number: send the text as it is, so the server says what is wrong with it.
  return trimmed !== '' && Number.isFinite(number) ? number : text;
}

/**
 * Write a tag after a confirmation. `preset` (a value) skips straight to the confirmation (a
 * mimic's button). Resolves true when the runtime accepted the write.
 */
export function openWrite(ctx, meta, preset) {
  return new Promise((resolve) => {
    let result = false;
    let box = null;
    const finish = () => { if (box) box.close(); };
    const unit = meta.unit || '';
    const current = () => ctx.live.get(meta.name);

    const form = el('form', { method: 'dialog', novalidate: true });
    const { facts, watch } = tagFacts(ctx, meta);
    const field = valueEntry(ctx, meta, { id: 'write-value', label: 'New value' });
    const entry = field.entry;
    const readValue = () => {
      const value = field.read();
      return meta.type === 'bool' || value === null ? value : parseInput(meta, value);
    };

    const message = el('div', { role: 'alert' });
    const stepValue = el('div', {}, entry);
    const change = el('div', { class: 'change num' });
    const stepConfirm = el('div', { hidden: true }, el('p', { class: 'muted small', text: 'Please confirm the write:' }), change);
    const back = el('button', { type: 'button', class: 'btn secondary', text: 'Back', hidden: true });
    const next = el('button', { type: 'submit', class: 'btn', text: 'Review' });
    const cancel = el('button', { type: 'button', class: 'btn secondary', text: 'Cancel', onclick: finish });
    let pending = null;

    const toConfirm = (value) => {
      pending = value;
      clear(change);
      const old = current() ? current().v : meta.value;
      change.append(
        el('span', { class: 'old', text: formatWithUnit(old, unit) }),
        el('span', { class: 'arrow', text: '→' }),
        el('strong', { class: 'new', text: formatExact(value, unit) }),  // exactly what will be written
      );
      clear(message);
      stepValue.hidden = true;
      stepConfirm.hidden = false;
      back.hidden = preset !== undefined;
      next.textContent = 'Confirm write';
      next.dataset.step = 'confirm';
      next.focus();
    };
    const toValue = () => {
      stepValue.hidden = false;
      stepConfirm.hidden = true;
      back.hidden = true;
      next.textContent = 'Review';
      next.dataset.step = 'value';
    };
    back.addEventListener('click', toValue);

    form.addEventListener('submit', async (event) => {
      event.preventDefault();
      if (next.dataset.step !== 'confirm') {
        const value = readValue();
        if (value === null) return;
        toConfirm(value);
        return;
      }
      next.disabled = true;
      clear(message);
      try {
        const answer = await writeTag(meta.name, pending);
        const item = answer.results && answer.results[0];
        if (item && item.ok) {
          result = true;
          message.append(el('div', { class: 'done', text: `Written: ${formatExact(item.value, unit)}. It applies at the next scan.` }));
          next.hidden = true;
          back.hidden = true;
          cancel.textContent = 'Close';
          setTimeout(finish, 1200);
        } else {
          const rule = item ? item.rule : 'refused';
          const detail = item ? item.detail : (answer.error || '');
          message.append(el('div', { class: 'refusal', 'data-rule': rule, text: `Refused — ${rule}: ${detail}` }));
          if (preset === undefined) toValue(); else next.hidden = true;
        }
      } catch (error) {
        message.append(el('div', { class: 'refusal', text: `Not written: ${error.message}` }));
      } finally {
        next.disabled = false;
      }
    });

    form.append(
      dialogHeading(`Write ${meta.name}`, finish),
      meta.description ? el('p', { class: 'desc', text: meta.description }) : null,
      facts, stepValue, stepConfirm, message,
      el('div', { class: 'actions' }, cancel, back, next),
    );
    box = showDialog(form);
    box.addEventListener('close', () => { watch.close(); resolve(result); }, { once: true });
    if (preset !== undefined) toConfirm(preset);
    else field.focus();
  });
}

/** Log in; resolves true on success (the caller refreshes the session). */
export function openLogin(ctx) {
  return new Promise((resolve) => {
    let ok = false;
    let box = null;
    const close = () => box && box.close();
    const user = el('input', { type: 'text', id: 'login-user', name: 'user', autocomplete: 'username', required: true });
    const password = el('input', { type: 'password', id: 'login-password', name: 'password', autocomplete: 'current-password', required: true });
    const message = el('div', { role: 'alert' });
    const submit = el('button', { type: 'submit', class: 'btn', text: 'Log in' });
    const form = el('form', { method: 'dialog' },
      dialogHeading('Log in', close),
      el('p', { class: 'muted small', text: 'The users of the runtime (softplc users add NAME --role ROLE), the same as for OPC UA.' }),
      el('label', { for: 'login-user', text: 'User' }), user,
      el('label', { for: 'login-password', text: 'Password' }), password,
      message,
      el('div', { class: 'actions' }, el('button', { type: 'button', class: 'btn secondary', text: 'Cancel', onclick: close }), submit),
    );
    form.addEventListener('submit', async (event) => {
      event.preventDefault();
      submit.disabled = true;
      clear(message);
      try {
        await post('/api/login', { user: user.value, password: password.value });
        ok = true;
        close();
      } catch (error) {
        message.append(el('div', { class: 'refusal', text: error.message }));
      } finally {
        submit.disabled = false;
      }
    });
    box = showDialog(form);
    box.addEventListener('close', () => resolve(ok), { once: true });
    user.focus();
  });
}

/** A live list of tags (a robot's, a task's...) with a write button where the role may write. */
export function openDetails(ctx, title, tags, subtitle) {
  const rows = new Map();
  const body = el('tbody');
  const reopen = () => openDetails(ctx, title, tags, subtitle);
  for (const meta of tags) {
    const value = el('span', { class: 'live-value' });
    const quality = el('span', { class: 'qual' });
    const forced = forcedMark(meta.forced);
    const write = meta.writable
      ? el('button', { type: 'button', class: 'btn small secondary', text: 'Write…', onclick: () => openWrite(ctx, meta).then(reopen) })
      : null;
    const force = forceControls(ctx, meta, reopen);  // engineers: force / unforce (ops/forcing.js)
    body.append(el('tr', { 'data-tag': meta.name },
      el('td', {}, el('a', { href: '#', class: 'tag-link', title: 'Details and trend', text: meta.name, onclick: async (event) => {
        event.preventDefault();
        (await import('./tag_details.js')).openTagDetails(ctx, meta);
      } }),
      meta.description ? el('span', { class: 'd', text: meta.description }) : null),
      el('td', { class: 'v' }, value, ' ', forced, el('br'), quality),
      el('td', { class: 'acts' }, write, force),
    ));
    rows.set(meta.name, { meta, value, quality, forced, force });
  }
  const update = (names) => {
    for (const name of names) {
      const row = rows.get(name);
      const item = ctx.live.get(name);
      if (!row || !item) continue;
      setText(row.value, formatWithUnit(item.v, row.meta.unit));
      row.value.className = `live-value ${item.q === 2 ? 'q-bad' : item.q === 1 ? 'q-uncertain' : ''}`;
      setText(row.quality, qualityName(item.q));
      row.quality.className = `qual ${qualityName(item.q)}`;
      showForced(row.forced, item.f);
      if (row.force && row.force.liveUpdate) row.force.liveUpdate(item);
    }
  };
  const watch = ctx.live.watch([...rows.keys()], update);
  update([...rows.keys()]);
  let box = null;
  const node = el('div', { class: 'body' },
    dialogHeading(title, () => box && box.close()),
    subtitle ? el('p', { class: 'muted small', text: subtitle }) : null,
    el('table', { class: 'detail-list' }, body),
  );
  box = showDialog(node, 'drawer');
  box.addEventListener('close', () => watch.close(), { once: true });
}

export { formatValue };
