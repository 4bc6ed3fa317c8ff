// The runtime's clock as the browser knows it: the latest runtime time heard (alarm messages,
// command answers, live values), moved on by the real time since at the session's speed. Under
// --sim the plant's time is not the browser's: "the last hour" of a trend and "since 4 min" of
// an alarm are counted on this clock, never on Date.now().

let last = null;  // {wall: runtime seconds, at: performance.now() when heard}

/** A runtime time (epoch seconds) just heard from the server. */
export function noteRuntimeTime(wall) {
  if (typeof wall !== 'number' || !Number.isFinite(wall)) return;
  if (!last || wall >= last.wall) last = { wall, at: performance.now() };
}

/** How fast the runtime clock runs against real time: 1 (real), N (--sim --speed N), 0 (as fast as possible: unknown). */
export function clockSpeed(session) {
  if (!session || !session.simulated) return 1;
  return typeof session.speed === 'number' ? session.speed : 0;
}

/** Now on the runtime clock, epoch seconds (the browser's clock until the runtime was heard). */
export function runtimeNow(session) {
  if (!last) return Date.now() / 1000;
  return last.wall + ((performance.now() - last.at) / 1000) * clockSpeed(session);
}

export function heardRuntime() { return last !== null; }
