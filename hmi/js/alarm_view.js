// How an alarm looks, the same on the banner, the alarm page and the journal: its priority as a
// shape AND a word AND a colour (ISA-101: never colour alone), its ISA-18.2 state in words with
// a mark (blinking while it waits for an acknowledgement), and times on the runtime clock.

import { el, svg } from './dom.js';

export const PRIORITIES = ['critical', 'high', 'medium', 'low'];
const PRIORITY_LABEL = { critical: 'Critical', high: 'High', medium: 'Medium', low: 'Low' };
const PRIORITY_RANK = { critical: 4, high: 3, medium: 2, low: 1 };

export function priorityRank(priority) { return PRIORITY_RANK[priority] || 0; }

/** The priority's shape: critical a diamond, high a triangle, medium a square, low a circle; hollow when the condition is gone. */
export function priorityIcon(priority, filled = true) {
  const shapes = {
    critical: () => svg('polygon', { points: '8,1 15,8 8,15 1,8' }),
    high: () => svg('polygon', { points: '8,1.5 15,14.5 1,14.5' }),
    medium: () => svg('rect', { x: 2, y: 2, width: 12, height: 12 }),
    low: () => svg('circle', { cx: 8, cy: 8, r: 6.5 }),
  };
  const shape = (shapes[priority] || shapes.low)();
  return svg('svg', { class: `prio-icon prio-${priority} ${filled ? 'filled' : 'hollow'}`, viewBox: '0 0 16 16', width: 16, height: 16, 'aria-hidden': 'true' }, shape);
}

/** A priority badge: shape and word. */
export function priorityBadge(priority, filled = true) {
  return el('span', { class: `prio prio-${priority}`, 'data-priority': priority },
    priorityIcon(priority, filled), el('span', { class: 'prio-text', text: PRIORITY_LABEL[priority] || priority }));
}

const STATE_TEXT = {
  unacknowledged: ['Active', 'unacknowledged'],
  acknowledged: ['Active', 'acknowledged'],
  returned: ['Cleared', 'unacknowledged'],
  latched: ['Latched', 'unacknowledged'],
  shelved: ['Shelved', ''],
  suppressed: ['Suppressed', 'by design'],
  out_of_service: ['Out of service', ''],
  normal: ['Normal', ''],
};
const STATE_MARK = { unacknowledged: '!', acknowledged: '✓', returned: '↓', latched: '⇲', shelved: '‖', suppressed: '⊘', out_of_service: '✕', normal: '' };

/** The state in words, e.g. "Active, unacknowledged"; a shelved alarm says until when (or one-shot). */
export function stateText(alarm, now) {
  const [first, second] = STATE_TEXT[alarm.state] || [alarm.state, ''];
  if (alarm.state === 'shelved' && alarm.shelving) {
    const until = alarm.shelving.kind === 'one_shot' ? 'one-shot, until it clears' : `until ${formatStamp(alarm.shelving.until, now)}`;
    return `${first} (${until})`;
  }
  return second ? `${first}, ${second}` : first;
}

/** A chip with the state's mark and words; `data-state` for tests and styles. */
export function stateChip(alarm, now) {
  return el('span', { class: `astate astate-${alarm.state}`, 'data-state': alarm.state },
    el('span', { class: 'astate-mark', 'aria-hidden': 'true', text: STATE_MARK[alarm.state] || '' }),
    el('span', { class: 'astate-text', text: stateText(alarm, now) }));
}

export function needsAcknowledgement(alarm) {
  return alarm.state === 'unacknowledged' || alarm.state === 'returned' || alarm.state === 'latched';
}

const pad = (n, w = 2) => String(n).padStart(w, '0');

/** A runtime time as the operator reads it: HH:MM:SS today (by `now`), else with the date. */
export function formatStamp(seconds, now) {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return '—';
  const date = new Date(seconds * 1000);
  const time = `${pad(date.getHours())}:${pad(date.getMinutes())}:${pad(date.getSeconds())}`;
  const today = new Date((now || seconds) * 1000);
  if (date.toDateString() === today.toDateString()) return time;
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())} ${time}`;
}

/** "42 s", "5 min", "3 h 10 min", "2 d 4 h". */
export function formatAge(seconds) {
  if (!Number.isFinite(seconds)) return '';
  const s = Math.max(0, Math.floor(seconds));
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min`;
  const both = (big, bigUnit, small, smallUnit) => (small ? `${big} ${bigUnit} ${small} ${smallUnit}` : `${big} ${bigUnit}`);
  if (s < 86400) return both(Math.floor(s / 3600), 'h', Math.floor((s % 3600) / 60), 'min');
  return both(Math.floor(s / 86400), 'd', Math.floor((s % 86400) / 3600), 'h');
}
