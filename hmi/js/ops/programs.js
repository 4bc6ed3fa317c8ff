// Program control and online change on the Tasks page (engineers): start / stop / restart a
// program after a confirmation, and an online change — checked first (programs.apply {check:
// true}: the differences, or the located problems and refusals, nothing applied), then applied on
// confirmation. Results show inline. The runtime decides (docs/runtime.md); a refusal is its words.

import { el, clear, setText } from '../dom.js';
import { command, isEngineer } from '../commands.js';
import { showDialog, dialogHeading } from '../dialog_box.js';

const VERBS = {
  start: { label: 'Start', done: 'Started', says: (p) => `Program ${p.name} runs its setup() again (a warm start) and is scanned from the next cycle of task ${p.task}.` },
  stop: { label: 'Stop', done: 'Stopped', says: (p) => `Program ${p.name} stops being scanned; its outputs take its fault reaction (${describe(p.on_fault)}).` },
  restart: { label: 'Restart', done: 'Restarted', says: (p) => `Program ${p.name} runs its setup() again (a warm start) and goes on scanning.` },
};

function describe(value) {
  if (value === undefined || value === null) return 'hold';
  return typeof value === 'string' ? value : JSON.stringify(value);
}

/** Add the controls to the Tasks page `root` (each program's element has data-program). Returns an unmount. */
export async function decoratePrograms(root, ctx, model) {
  const engineer = isEngineer(ctx.session);
  const runtimePanel = root.querySelector('section.panel');
  if (!engineer) {
    runtimePanel.append(el('p', { class: 'muted small', text: 'Starting, stopping and restarting programs and online changes need the engineer role.' }));
    return () => {};
  }
  const entries = new Map();  // program → {node, buttons, result, version}
  for (const node of root.querySelectorAll('[data-program]')) {
    const buttons = new Map();
    const bar = el('div', { class: 'program-actions' });
    for (const [action, verb] of Object.entries(VERBS)) {
      const button = el('button', { type: 'button', class: `btn small ${action === 'stop' ? 'danger' : 'secondary'}`, text: `${verb.label}…`,
        'data-action': action, disabled: true, onclick: () => confirmAction(node.dataset.program, action) });
      buttons.set(action, button);
      bar.append(button);
    }
    const version = el('span', { class: 'muted small version' });
    const result = el('div', { class: 'program-result small', role: 'status' });
    node.append(bar, version, result);
    entries.set(node.dataset.program, { node, buttons, result, version, info: null });
  }

  const refresh = async () => {
    const answer = await command('programs.list', {});
    if (!answer.ok) return;
    for (const info of answer.result) {
      const entry = entries.get(info.name);
      if (!entry) continue;
      entry.info = info;
      for (const [action, button] of entry.buttons) button.disabled = !info.actions.includes(action);
      setText(entry.version, info.version > 1 ? `version ${info.version} (online changes applied)` : '');
    }
  };
  let timer = null;
  const soon = () => { clearTimeout(timer); timer = setTimeout(refresh, 50); };
  const states = model.tasks.flatMap((task) => task.programs.map((program) => `${program.prefix}state`));
  const watch = ctx.live.watch(states, soon);

  const confirmAction = (name, action) => {
    const entry = entries.get(name);
    const info = entry.info || { name, task: '?', on_fault: 'hold' };
    const verb = VERBS[action];
    const message = el('div', { role: 'alert' });
    const go = el('button', { type: 'submit', class: `btn ${action === 'stop' ? 'danger' : ''}`, text: `${verb.label} ${name}` });
    const cancel = el('button', { type: 'button', class: 'btn secondary', text: 'Cancel' });
    const form = el('form', { method: 'dialog', novalidate: true });
    let box = null;
    cancel.addEventListener('click', () => box.close());
    form.append(dialogHeading(`${verb.label} program ${name}?`, () => box.close()),
      el('p', { text: verb.says(info) }),
      el('p', { class: 'muted small', text: `It is ${info.state || 'in an unknown state'} now; the change lasts until the runtime stops (enabled: in the file says how it starts).` }),
      message, el('div', { class: 'actions' }, cancel, go));
    form.addEventListener('submit', async (event) => {
      event.preventDefault();
      go.disabled = true;
      const answer = await command(`programs.${action}`, { program: name });
      clear(message);
      clear(entry.result);
      if (answer.ok) {
        message.append(el('div', { class: 'done', text: `${answer.result}` }));
        entry.result.append(el('span', { class: 'done-text', text: `${verb.done}: ${answer.result}` }));
        go.hidden = true;
        cancel.textContent = 'Close';
      } else {
        message.append(el('div', { class: 'refusal', text: `Refused — ${answer.error}` }));
        entry.result.append(el('span', { class: 'error-text', text: `${verb.label} refused: ${answer.error}` }));
        go.disabled = false;
      }
      refresh();
    });
    box = showDialog(form);
    go.focus();
  };

  runtimePanel.after(onlineChangePanel(ctx, model, refresh));
  await refresh();
  return () => { watch.close(); clearTimeout(timer); };
}

/** The online change: check (differences or located problems), then apply on confirmation. */
function onlineChangePanel(ctx, model, refresh) {
  const last = el('div', { class: 'online-result', role: 'status' });
  const button = el('button', { type: 'button', class: 'btn', text: 'Online change…', 'data-online-change': 'check' });
  const panel = el('section', { class: 'panel online-change' },
    el('div', { class: 'panel-head' }, el('h2', { text: 'Online change' })),
    el('p', { class: 'small muted', text: 'Edit a program\'s Python module or its params/bind/on_fault in the plant\'s file, then check and apply the change here without stopping the plant. It is checked first: nothing is applied if anything is wrong.' }),
    el('div', { class: 'toolbar' }, button), last);
  button.addEventListener('click', async () => {
    button.disabled = true;
    try {
      await openOnlineChange(last, refresh);
    } finally {
      button.disabled = false;
    }
  });
  return panel;
}

function lines(title, items, className) {
  if (!items || !items.length) return null;
  return el('div', { class: `change-list ${className || ''}` }, el('h3', { text: title }), el('ul', {}, ...items.map((item) => el('li', { text: item }))));
}

async function openOnlineChange(last, refresh) {
  const status = el('p', { class: 'muted', role: 'status', text: 'Checking the file (programs.apply, check only)…' });
  const report = el('div', { class: 'online-report' });
  const apply = el('button', { type: 'submit', class: 'btn danger', text: 'Apply online change', hidden: true, 'data-online-change': 'apply' });
  const cancel = el('button', { type: 'button', class: 'btn secondary', text: 'Cancel' });
  const form = el('form', { method: 'dialog', novalidate: true });
  let box = null;
  cancel.addEventListener('click', () => box.close());
  form.append(dialogHeading('Online change', () => box.close()), status, report, el('div', { class: 'actions' }, cancel, apply));
  box = showDialog(form, 'wide');
  const refused = (answer, phase) => {
    const details = answer.details || {};
    setText(status, `${phase} refused — nothing applied.`);
    status.className = 'refusal';
    report.replaceChildren(...[
      lines('Problems', details.problems, 'problems'),
      lines('Needs a restart of the runtime', details.needs_restart, 'problems'),
      lines('Differences (not applied)', (details.changes || []).filter((line) => !line.startsWith('needs a restart: ')), ''),
      details.problems || details.needs_restart ? null : el('p', { class: 'error-text', text: answer.error }),
    ].filter(Boolean));
    clear(last);
    last.append(el('span', { class: 'error-text', text: `Online change refused, nothing applied: ${firstLine(answer.error)}` }));
  };
  const check = await command('programs.apply', { check: true });
  if (!check.ok) {
    refused(check, 'Check');
    return;
  }
  const result = check.result;
  if (!result.changes.length) {
    setText(status, result.summary);
    cancel.textContent = 'Close';
    clear(last);
    last.append(el('span', { class: 'muted', text: result.summary }));
    return;
  }
  setText(status, `Checked: these differences from the running programs can be applied now (${result.file}).`);
  report.replaceChildren(lines('Differences', result.changes, ''));
  apply.hidden = false;
  apply.focus();
  form.addEventListener('submit', async (event) => {
    event.preventDefault();
    apply.disabled = true;
    setText(status, 'Applying at a scan boundary…');
    const answer = await command('programs.apply', {});
    apply.hidden = true;
    cancel.textContent = 'Close';
    if (!answer.ok) {
      refused(answer, 'Apply');
      return;
    }
    status.className = 'done';
    setText(status, answer.result.summary);
    const programs = (answer.result.programs || []).map((entry) => `${entry.name} (task ${entry.task}, now ${entry.state}): ${entry.changes.join('; ')}`
      + (entry.carried_over ? ` — state carried over: ${entry.carried_over.join(', ') || 'nothing'}` : ''));
    report.replaceChildren(lines('Applied', programs, ''));
    clear(last);
    last.append(el('span', { class: 'done-text', text: answer.result.summary }));
    refresh();
  }, { once: true });
}

function firstLine(text) { return String(text || '').split('\n').slice(0, 2).join(' '); }
