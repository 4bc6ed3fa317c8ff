// How values look: numbers with sensible digits, booleans, text, qualities, times.

import { qualityName } from './live.js';

export function formatNumber(value, decimals) {
  if (typeof value !== 'number') return String(value);
  if (decimals !== undefined && decimals !== null) return value.toFixed(decimals);
  if (Number.isInteger(value)) return String(value);
  const size = Math.abs(value);
  const digits = size >= 1000 ? 0 : size >= 100 ? 1 : size >= 1 ? 2 : 3;
  return value.toFixed(digits);
}

/** A value as text ("—" when unknown); `meta` is the tag's declaration when known. */
export function formatValue(value, meta, decimals) {
  if (value === undefined || value === null) return '—';
  if (typeof value === 'boolean') return value ? 'true' : 'false';
  if (typeof value === 'number') return formatNumber(value, decimals);
  return String(value);  // text, or "NaN"/"Infinity" for a non-finite float
}

export function formatWithUnit(value, unit, decimals) {
  const text = formatValue(value, null, decimals);
  return unit && value !== undefined && value !== null ? `${text} ${unit}` : text;
}

/** A value exactly as written or forced (a number unrounded), with its unit. */
export function formatExact(value, unit) {
  const text = typeof value === 'number' ? String(value) : formatValue(value);
  return unit ? `${text} ${unit}` : text;
}

/** CSS class of a value by its quality code (0 good, 1 uncertain, 2 bad). */
export function qualityClass(code) {
  return code === 1 ? 'q-uncertain' : code === 2 ? 'q-bad' : '';
}

export { qualityName };

export function formatTime(seconds) {
  if (!seconds) return '—';
  const date = new Date(seconds * 1000);
  const pad = (n, w = 2) => String(n).padStart(w, '0');
  return `${pad(date.getHours())}:${pad(date.getMinutes())}:${pad(date.getSeconds())}.${pad(date.getMilliseconds(), 3)}`;
}

export function formatRange(meta) {
  if (!meta) return '';
  const low = meta.min === null || meta.min === undefined ? null : formatNumber(meta.min);
  const high = meta.max === null || meta.max === undefined ? null : formatNumber(meta.max);
  if (low === null && high === null) return '';
  return `${low ?? '…'} … ${high ?? '…'}`;
}

export const NAVSTATE_CLASS = { moving: 'ok', planning: 'info', blocked: 'warn', failed: 'bad', idle: 'idle', arrived: 'idle', offline: 'bad' };
export const CURRLOC_TEXT = ['waiting for a task', 'to source', 'at source (loading)', 'to destination', 'at destination (unloading)'];
