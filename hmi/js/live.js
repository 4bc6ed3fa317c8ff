// The live channel: one WebSocket per browser tab (docs/hmi.md, "Live protocol").
//
// Pages `watch(names, callback)`; the channel subscribes the union of what every open watcher
// needs and calls each back with the names that changed. It never freezes silently: a closed
// socket, or nothing heard for 2.5 heartbeats, switches to "disconnected" at once, and it
// reconnects by itself (0.5 s, 1 s, 2 s ... 5 s) and re-synchronises from a fresh snapshot.

const QUALITY = ['good', 'uncertain', 'bad'];

export class Live extends EventTarget {
  constructor(url) {
    super();
    this.url = url || `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/api/live`;
    this.values = new Map();          // name → {v, q, t, f} (f: forced)
    this.state = 'connecting';        // connecting | live | disconnected | stopped (on purpose)
    this.reason = '';
    this.heartbeat = 2.0;
    this.instance = null;
    this.synced = false;              // the current subscription's snapshot has arrived
    this._watchers = new Set();
    this._index = new Map();          // name → Set(watcher)
    this._socket = null;
    this._retry = 0;
    this._retryTimer = null;
    this._lastHeard = 0;
    this._timer = null;
    this._pendingSubscribe = false;
    this._stopped = false;
    this._subscriptionId = 0;         // the number of the last subscription sent ...
    this._answeredId = -1;            // ... and of the last one the server said it applied (then its snapshot follows)
  }

  connect() {
    this._stopped = false;
    clearTimeout(this._retryTimer);
    const socket = new WebSocket(this.url);
    this._socket = socket;
    this._setState('connecting', '');
    socket.addEventListener('open', () => {
      if (socket !== this._socket) return;
      this._lastHeard = performance.now();
      this._sendSubscription(true);
    });
    socket.addEventListener('message', (event) => {
      if (socket !== this._socket) return;
      this._lastHeard = performance.now();
      this._receive(event.data);
    });
    socket.addEventListener('close', (event) => {
      if (socket !== this._socket) return;
      const why = event.code === 1001 ? 'the runtime stopped' : event.code === 1006 ? 'connection lost' : (event.reason || 'connection closed');
      this._lost(why);
    });
    socket.addEventListener('error', () => { /* a close event follows */ });
    if (!this._timer) this._timer = setInterval(() => this._tick(), 500);
  }

  /** Close the channel on purpose (e.g. until a login): state 'stopped', no reconnecting until connect(). */
  stop() {
    this._stopped = true;
    clearInterval(this._timer);
    this._timer = null;
    clearTimeout(this._retryTimer);
    if (this._socket) this._socket.close();
    this._socket = null;
    this.synced = false;
    this._setState('stopped', '');
  }

  /** Reconnect now (e.g. after logging in: the socket carries the identity). */
  reconnect() {
    if (this._socket) {
      const old = this._socket;
      this._socket = null;
      old.close();
    }
    this._retry = 0;
    this.connect();
  }

  get(name) { return this.values.get(name); }

  /** Watch item names; `callback(changedNames)` after each message touching them. */
  watch(names, callback) {
    const watcher = { names: new Set(names), callback };
    this._watchers.add(watcher);
    this._indexAdd(watcher);
    this._resubscribe();
    const live = this;
    return {
      update(newNames) {
        live._indexRemove(watcher);
        watcher.names = new Set(newNames);
        live._indexAdd(watcher);
        live._resubscribe();
      },
      close() {
        live._indexRemove(watcher);
        live._watchers.delete(watcher);
        live._resubscribe();
      },
    };
  }

  // -- internals -------------------------------------------------------------------------------

  _indexAdd(watcher) {
    for (const name of watcher.names) {
      let set = this._index.get(name);
      if (!set) this._index.set(name, (set = new Set()));
      set.add(watcher);
    }
  }

  _indexRemove(watcher) {
    for (const name of watcher.names) {
      const set = this._index.get(name);
      if (set) { set.delete(watcher); if (!set.size) this._index.delete(name); }
    }
  }

  _resubscribe() {
    if (this._pendingSubscribe) return;
    this._pendingSubscribe = true;
    queueMicrotask(() => { this._pendingSubscribe = false; this._sendSubscription(); });
  }

  /** Send the watched names; unless `always` (a new socket), only when they differ from the last sent. */
  _sendSubscription(always = false) {
    const socket = this._socket;
    if (!socket || socket.readyState !== WebSocket.OPEN) return;
    const names = this._index;
    const sent = this._subscribed;
    // A page that re-watches the same names (a banner refreshing, a list re-rendering) must not
    // cost a fresh snapshot of all of them: the server would send one for every subscribe.
    if (!always && sent && sent.size === names.size && [...names.keys()].every((name) => sent.has(name))) return;
    this._subscribed = new Set(names.keys());
    this.synced = false;
    this._subscriptionId += 1;  // only grows: an answer on an earlier socket never matches a later request
    socket.send(JSON.stringify({ type: 'subscribe', items: [...this._subscribed], id: this._subscriptionId }));
  }

  _receive(text) {
    let message;
    try { message = JSON.parse(text); } catch { return; }
    switch (message.type) {
      case 'hello': {
        this.heartbeat = message.heartbeat || 2.0;
        const restarted = this.instance !== null && this.instance !== message.instance;
        this.instance = message.instance;
        this._retry = 0;
        this._setState('live', '');
        this.dispatchEvent(new CustomEvent('hello', { detail: { ...message, restarted } }));
        break;
      }
      case 'snapshot':
      case 'update': {
        // {time, values: {name: value}, times: {name: t} (exceptions), quality: {name: code} (not good),
        //  forced: [name, ...] (forced items; the others of the message are not)}
        const changed = [];
        const times = message.times || {};
        const quality = message.quality || {};
        const forced = new Set(message.forced || []);
        for (const [name, value] of Object.entries(message.values || {})) {
          this.values.set(name, { v: value, q: quality[name] || 0, t: times[name] ?? message.time, f: forced.has(name) });
          changed.push(name);
        }
        this._notify(changed);
        // Synced only by the snapshot of the current subscription: one sent for an earlier set
        // (the shell's names, just before a view added its own) may arrive after the new request.
        if (message.type === 'snapshot' && message.done && this._answeredId === this._subscriptionId) {
          this.synced = true;
          this.dispatchEvent(new CustomEvent('synced'));
        }
        break;
      }
      case 'subscribed':
        this._answeredId = message.id;
        break;
      case 'ping':
        this._send({ type: 'pong' });
        break;
      case 'unknown':
        console.warn(`HMI: ${message.count} unknown items`, message.items);
        break;
      case 'error':
        console.warn('HMI live channel:', message.message);
        break;
      default:  // other kinds (e.g. "alarms", alarm_feed.js) go to whoever listens for them
        this.dispatchEvent(new CustomEvent('message', { detail: message }));
        break;
    }
  }

  _notify(changed) {
    if (!changed.length) return;
    const touched = new Map();
    for (const name of changed) {
      const set = this._index.get(name);
      if (!set) continue;
      for (const watcher of set) {
        let list = touched.get(watcher);
        if (!list) touched.set(watcher, (list = []));
        list.push(name);
      }
    }
    for (const [watcher, names] of touched) {
      try { watcher.callback(names); } catch (error) { console.error('HMI watcher failed', error); }
    }
  }

  /** Send a message of another kind (e.g. {type: 'alarms', on: true}); dropped while not connected. */
  send(message) { this._send(message); }

  _send(message) {
    const socket = this._socket;
    if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
  }

  _tick() {
    if (this.state !== 'live') return;
    const silent = (performance.now() - this._lastHeard) / 1000;
    if (silent > 2.5 * this.heartbeat) {
      const socket = this._socket;
      this._socket = null;
      if (socket) socket.close();
      this._lost(`no word from the runtime for ${silent.toFixed(1)} s`);
      return;
    }
    if (!this._lastPing || performance.now() - this._lastPing > this.heartbeat * 1000) {
      this._lastPing = performance.now();
      this._send({ type: 'ping' });
    }
  }

  _lost(reason) {
    this._socket = null;
    this.synced = false;
    if (this._stopped) return;
    const delay = Math.min(5, 0.5 * 2 ** this._retry);
    this._retry += 1;
    this._setState('disconnected', reason, delay);
    clearTimeout(this._retryTimer);
    this._retryTimer = setTimeout(() => this.connect(), delay * 1000);
  }

  _setState(state, reason, retryIn) {
    this.state = state;
    this.reason = reason;
    this.dispatchEvent(new CustomEvent('state', { detail: { state, reason, retryIn } }));
  }
}

export function qualityName(code) { return QUALITY[code] || 'bad'; }
