// Calling the runtime's commands (forcing, program control, online change, the audit trail) through
// the HMI's door, POST /api/commands/NAME (softplc/hmi/command_door.py, and ../commands.js): the
// session's role is checked by the runtime, like on every other path; a refusal comes back with the
// runtime's own words, and an online change's refusal with its details.

import { callWithTime } from '../commands.js';

/** {ok: true, result} or {ok: false, status, error, details}; never throws for a refusal. */
export async function command(name, args) {
  try {
    return { ok: true, result: (await callWithTime(name, args || {})).result };
  } catch (error) {
    const body = error.body || {};
    return { ok: false, status: error.status || 0, error: body.error || error.message, details: body.details || null };
  }
}

export function isEngineer(session) { return Boolean(session && session.role === 'engineer'); }
