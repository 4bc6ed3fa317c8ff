// Times on a trend's axis and in its legend: 24-hour, in the browser's time zone, like every other
// page (format.js); the date under the first label and under the first label of each new day.

const pad = (number, width = 2) => String(number).padStart(width, '0');

function day(date) { return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())}`; }

/** "2026-01-01 14:05:09": a moment in full (the legend's time under the cursor). */
export function fullTime(seconds) {
  const date = new Date(seconds * 1000);
  return `${day(date)} ${pad(date.getHours())}:${pad(date.getMinutes())}:${pad(date.getSeconds())}`;
}

/** uPlot's `values` for the time axis: labels for `splits` (seconds) `step` seconds apart. */
export function timeLabels(u, splits, axis, space, step) {
  let shownDay = null;
  return splits.map((seconds) => {
    const date = new Date(seconds * 1000);
    const hours = `${pad(date.getHours())}:${pad(date.getMinutes())}`;
    let text;
    if (step >= 86400) text = `${pad(date.getMonth() + 1)}-${pad(date.getDate())}`;
    else if (step >= 60) text = hours;
    else if (step >= 1) text = `${hours}:${pad(date.getSeconds())}`;
    else text = `${hours}:${pad(date.getSeconds())}.${pad(date.getMilliseconds(), 3).slice(0, step >= 0.1 ? 1 : 2)}`;
    const today = day(date);
    if (step < 86400 && today !== shownDay) text += `\n${today}`;  // the date where it begins or changes
    else if (step >= 86400 && (shownDay === null || today.slice(0, 4) !== shownDay.slice(0, 4))) text += `\n${date.getFullYear()}`;
    shownDay = today;
    return text;
  });
}
