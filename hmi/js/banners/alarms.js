// The alarm banner under the header of every page: the most severe alarm waiting for an
// acknowledgement (priority shape and word, name, message, since when), the counts, and an
// optional sound (off by default; the choice is remembered by this browser). Click it for the
// alarm page. Live: the alarm feed of the live channel (alarm_feed.js), no polling.

import { el, svg, clear, setText } from '../dom.js';
import { alarmFeed } from '../alarm_feed.js';
import { priorityBadge, formatStamp, formatAge } from '../alarm_view.js';
import { runtimeNow } from '../runtime_clock.js';

const SOUND_KEY = 'softplc.alarmSound';
const SOUND_TRANSITIONS = new Set(['activated', 'realarmed']);
const MIN_TONE_GAP = 2000;  // ms: a flood of alarms is one tone, not a siren

let audio = null;

function soundWanted() {
  try { return localStorage.getItem(SOUND_KEY) === 'on'; } catch { return false; }
}

function rememberSound(on) {
  try { localStorage.setItem(SOUND_KEY, on ? 'on' : 'off'); } catch { /* private mode: for this page only */ }
}

/** Two short beeps made by WebAudio (no sound file to serve). */
function tone() {
  const Context = window.AudioContext || window.webkitAudioContext;
  if (!Context) return false;
  audio = audio || new Context();
  if (audio.state === 'suspended') audio.resume();
  const start = audio.currentTime + 0.01;
  for (const offset of [0, 0.22]) {
    const oscillator = audio.createOscillator();
    const gain = audio.createGain();
    oscillator.type = 'sine';
    oscillator.frequency.value = 880;
    gain.gain.setValueAtTime(0.0001, start + offset);
    gain.gain.exponentialRampToValueAtTime(0.25, start + offset + 0.02);
    gain.gain.exponentialRampToValueAtTime(0.0001, start + offset + 0.16);
    oscillator.connect(gain).connect(audio.destination);
    oscillator.start(start + offset);
    oscillator.stop(start + offset + 0.18);
  }
  return true;
}

/** A speaker with sound waves, or struck out. */
function speaker(on) {
  return svg('svg', { class: 'speaker', viewBox: '0 0 16 16', width: 16, height: 16, 'aria-hidden': 'true' },
    svg('path', { d: 'M2 6h3l4-3v10l-4-3H2z', class: 'speaker-body' }),
    on ? svg('path', { d: 'M11 5.5a3.5 3.5 0 0 1 0 5M12.8 3.5a6 6 0 0 1 0 9', class: 'speaker-wave' })
      : svg('path', { d: 'M11 5.5l4 5M15 5.5l-4 5', class: 'speaker-wave' }));
}

export function mount(node, ctx) {
  const feed = alarmFeed(ctx.live);
  let soundOn = soundWanted();
  let lastTone = -Infinity;
  let tones = 0;

  const main = el('span', { class: 'ab-main' });
  const counts = el('span', { class: 'ab-counts' });
  const link = el('a', { class: 'ab-link', href: '#/alarms', title: 'Open the alarm page' }, main, counts);
  const sound = el('button', { type: 'button', class: 'ab-sound', 'aria-label': 'Alarm sound' });
  const bar = el('div', { class: 'alarm-banner', id: 'alarm-banner', role: 'status', 'aria-live': 'polite', 'data-level': 'none' }, link, sound);
  node.append(bar);

  const showSound = () => {
    sound.setAttribute('aria-pressed', soundOn ? 'true' : 'false');
    clear(sound).append(speaker(soundOn), el('span', { text: soundOn ? 'Sound on' : 'Sound off' }));
    sound.title = soundOn ? 'New alarms beep (click to silence)' : 'New alarms are silent (click for a beep)';
  };
  sound.addEventListener('click', () => {
    soundOn = !soundOn;
    rememberSound(soundOn);
    showSound();
    if (soundOn) tone();  // a click is the gesture browsers want before they play sound
  });
  // A sound remembered from an earlier visit may only start after the first click on the page.
  const unlock = () => { if (soundOn && audio && audio.state === 'suspended') audio.resume(); };
  document.addEventListener('pointerdown', unlock);

  const render = () => {
    const summary = feed.summary;
    clear(main);
    clear(counts);
    if (!feed.synced || !summary) {
      bar.dataset.level = 'unknown';
      main.append(el('span', { class: 'ab-quiet', text: ctx.live.state === 'live' ? 'Alarms: loading…' : 'Alarms: not connected — state unknown' }));
      return;
    }
    const worst = summary.most_severe_unacknowledged;
    const now = runtimeNow(ctx.session);
    if (worst) {
      bar.dataset.level = worst.priority;
      bar.dataset.alarm = worst.name;
      main.append(
        priorityBadge(worst.priority, worst.active),
        el('strong', { class: 'ab-name', text: worst.name }),
        el('span', { class: 'ab-message', text: worst.message }),
        el('span', { class: 'ab-since', text: `since ${formatStamp(worst.since, now)}` }),
      );
    } else {
      bar.dataset.level = summary.active ? 'acknowledged' : 'none';
      delete bar.dataset.alarm;
      main.append(el('span', { class: 'ab-quiet', text: summary.active ? 'All alarms acknowledged' : 'No alarms' }));
    }
    const count = (key, label) => el('span', { class: 'ab-count', 'data-count': key }, el('b', { class: 'num', text: String(summary[key] || 0) }), ` ${label}`);
    counts.append(count('active', 'active'), count('unacknowledged', 'unack.'), count('shelved', 'shelved'));
    counts.title = `${summary.active} active, ${summary.unacknowledged} waiting for acknowledgement, ${summary.shelved} shelved`;
    if (worst) counts.title += ` — oldest shown for ${formatAge(now - worst.since)}`;
  };

  const stop = feed.use((change) => {
    render();
    if (!soundOn || change.snapshot) return;
    const fresh = change.transitions.some((t) => SOUND_TRANSITIONS.has(t.transition) && t.state === 'unacknowledged');
    if (fresh && performance.now() - lastTone > MIN_TONE_GAP) {
      lastTone = performance.now();
      if (tone()) bar.dataset.tones = String(++tones);
    }
  });
  showSound();
  render();
  return () => {
    stop();
    document.removeEventListener('pointerdown', unlock);
  };
}
