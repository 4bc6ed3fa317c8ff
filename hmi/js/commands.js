// The door to the runtime's commands (docs/hmi.md, "Commands"): every action of the alarm, journal,
// trend, forced, tasks and audit pages — acknowledge, shelve, read history, force, start a program,
// apply an online change, read the audit trail — is POST /api/commands/NAME with the arguments as
// JSON, checked by role on the server like every other path (OPC UA, CLI).

import { get, post } from './api.js';

/** Call a command; resolves to its result, rejects with an ApiError whose message is the refusal. */
export async function call(name, args = {}) {
  const answer = await post(`/api/commands/${encodeURIComponent(name)}`, args);
  return answer.result;
}

/** Call a command; resolves to the whole answer {ok, result, time} (the runtime clock's time too). */
export async function callWithTime(name, args = {}) {
  return post(`/api/commands/${encodeURIComponent(name)}`, args);
}

/** Call a command without throwing for a refusal: {ok: true, result} or {ok: false, status, error, details}. */
export async function command(name, args = {}) {
  try {
    return { ok: true, result: await call(name, args) };
  } catch (error) {
    const body = error.body || {};
    return { ok: false, status: error.status || 0, error: body.error || error.message, details: body.details || null };
  }
}

export function isEngineer(session) { return Boolean(session && session.role === 'engineer'); }

let allowedCache = { key: null, answer: null };

/** Which commands the session's role may call: Map name → true/false (asked once per user and role). */
export async function allowedCommands(session) {
  const key = `${session.user || ''}|${session.role || ''}`;
  if (allowedCache.key !== key || !allowedCache.answer) {
    const answer = get('/api/commands').then((data) => new Map(data.commands.map((command) => [command.name, command.allowed])));
    allowedCache = { key, answer };
    answer.catch(() => { if (allowedCache.answer === answer) allowedCache = { key: null, answer: null }; });
  }
  return allowedCache.answer;
}
