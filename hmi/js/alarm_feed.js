// Alarms over the live channel (docs/hmi.md, "Live alarms"): one feed per live channel, shared by
// the banner and the alarm page. It asks the server for the alarms after every (re)connection,
// gets a snapshot of every alarm that is not normal, then the changes (at most 10 a second).

import { noteRuntimeTime } from './runtime_clock.js';

const feeds = new WeakMap();

/** The feed of a live channel (made on first use). */
export function alarmFeed(live) {
  let feed = feeds.get(live);
  if (!feed) {
    feed = new AlarmFeed(live);
    feeds.set(live, feed);
  }
  return feed;
}

class AlarmFeed {
  constructor(live) {
    this.live = live;
    this.alarms = new Map();   // name → alarm (alarms.list's dict), normal ones left out
    this.summary = null;       // alarms.summary's answer
    this.synced = false;       // a snapshot arrived on the current connection
    this._listeners = new Set();
    live.addEventListener('hello', () => this._ask());
    live.addEventListener('message', (event) => { if (event.detail.type === 'alarms') this._receive(event.detail); });
    live.addEventListener('state', (event) => {
      if (event.detail.state !== 'live' && this.synced) {
        this.synced = false;
        this._notify({ stale: true, changed: [], transitions: [] });
      }
    });
  }

  /** Follow the alarms: `callback({snapshot, stale, changed, transitions})` after each message; returns a stop function. */
  use(callback) {
    this._listeners.add(callback);
    if (this._listeners.size === 1 || !this.synced) this._ask();
    return () => {
      this._listeners.delete(callback);
      if (!this._listeners.size) {
        this.live.send({ type: 'alarms', on: false });
        this.synced = false;
      }
    };
  }

  list() { return [...this.alarms.values()]; }

  get(name) { return this.alarms.get(name); }

  _ask() {
    if (this._listeners.size && this.live.state === 'live') this.live.send({ type: 'alarms', on: true });
  }

  _receive(message) {
    noteRuntimeTime(message.time);
    const changed = [];
    if (message.snapshot) {
      this.alarms.clear();
      this.synced = true;
    }
    for (const alarm of message.alarms || []) {
      if (alarm.state === 'normal') this.alarms.delete(alarm.name);
      else this.alarms.set(alarm.name, alarm);
      changed.push(alarm.name);
    }
    if (message.summary) this.summary = message.summary;
    this._notify({ snapshot: Boolean(message.snapshot), stale: false, changed, transitions: message.transitions || [] });
  }

  _notify(change) {
    for (const callback of this._listeners) {
      try { callback(change); } catch (error) { console.error('HMI alarm listener failed', error); }
    }
  }
}
