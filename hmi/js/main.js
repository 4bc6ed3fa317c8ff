// The page shell: session, navigation built from the server's page list, the live channel, the
// connection and runtime state in the header, the banner slot, and the router (#/PAGE?k=v).
//
// A page is an ES module exporting `mount(root, context)` that returns an unmount function;
// `context` = {live, session, params, openWrite(meta, preset), openDetails(title, tags, subtitle),
// navigate(hash)}. Other modules add pages, banners and API routes on the server (softplc/adapters/hmi/shell.py).

import { el, clear, setText } from './dom.js';
import { get, post, setCsrf, forgetMeta } from './api.js';
import { Live } from './live.js';
import { openWrite, openLogin, openDetails } from './dialogs.js';

const state = { session: null, live: null, unmount: null, pageId: null, banners: [], failed: false, booted: false, showConnection: () => {} };

function context(params) {
  return {
    live: state.live,
    session: state.session,
    params,
    openWrite: (meta, preset) => openWrite(contextBase(), meta, preset),
    openDetails: (title, tags, subtitle) => openDetails(contextBase(), title, tags, subtitle),
    navigate: (hash) => { location.hash = hash; },
  };
}
function contextBase() { return { live: state.live, session: state.session }; }

async function loadSession() {
  const session = await get('/api/session');
  state.session = session;
  setCsrf(session.csrf);
  document.title = `${session.plant.name} — softplc HMI`;
  setText(document.getElementById('plant-name'), session.plant.name);
  document.getElementById('plant-name').title = session.plant.description || '';
  return session;
}

function renderNav() {
  const nav = clear(document.getElementById('nav'));
  let group = null;
  for (const page of state.session.pages) {
    if (page.group !== group && nav.childElementCount) nav.append(el('span', { class: 'group-sep', 'aria-hidden': 'true' }));
    group = page.group;
    nav.append(el('a', { href: `#/${page.id}`, 'data-page': page.id, text: page.title }));
  }
  markNav();
}

function markNav() {
  for (const link of document.querySelectorAll('#nav a')) {
    if (link.dataset.page === state.pageId) link.setAttribute('aria-current', 'page');
    else link.removeAttribute('aria-current');
  }
}

function renderUser() {
  const box = clear(document.getElementById('user-box'));
  const session = state.session;
  if (session.user) {
    box.append(
      // On a phone a long name is shortened, never the role.
      el('span', { class: 'who', 'data-role': session.role, title: `${session.user} · ${session.role}` },
        el('span', { class: 'user-name', text: session.user }), '\u00a0·\u00a0', el('span', { class: 'role', text: session.role })),
      el('button', { type: 'button', text: 'Log out', onclick: logout }),
    );
  } else {
    if (session.role) {
      box.append(el('span', { class: 'who', 'data-role': session.role },
        el('span', { class: 'user-name', text: 'visitor' }), '\u00a0·\u00a0', el('span', { class: 'role', text: session.role })));
    }
    box.append(el('button', { type: 'button', text: 'Log in', onclick: login }));
  }
}

async function login() {
  if (await openLogin(contextBase())) await restart();
}

async function logout() {
  try { await post('/api/logout', {}); } catch { /* the session is gone anyway */ }
  await restart();
}

/** After a login, a logout or a runtime restart: new identity, new page list, fresh values. */
async function restart() {
  forgetMeta();
  await start();
  state.failed = false;
  if (!state.session.login_required) state.live.reconnect();
}

function route() {
  const hash = location.hash.replace(/^#\/?/, '');
  const [id, query] = hash.split('?');
  const pages = state.session.pages;
  const page = pages.find((p) => p.id === id) || pages[0];
  const params = { ...page.params, ...Object.fromEntries(new URLSearchParams(query || '')) };
  show(page, params);
}

async function show(page, params) {
  if (state.unmount) {
    try { state.unmount(); } catch (error) { console.error(error); }
    state.unmount = null;
  }
  state.pageId = page.id;
  markNav();
  const root = clear(document.getElementById('page'));
  root.dataset.page = page.id;
  delete root.dataset.ready;  // the page sets it again once it shows live values
  try {
    const module = await import(page.module);
    if (state.pageId !== page.id) return;  // another page was opened meanwhile
    state.unmount = await module.mount(root, context(params)) || null;
  } catch (error) {
    console.error(error);
    root.append(el('div', { class: 'error-banner', role: 'alert', text: `This page could not be shown: ${error.message}` }));
  }
}

function showLoginPage() {
  // No live channel before the login (the runtime refuses it): that is no outage, so say neither
  // "disconnected" nor a runtime state this visitor may not see.
  state.live.stop();
  showNotLive();
  const root = clear(document.getElementById('page'));
  clear(document.getElementById('nav'));
  root.append(el('div', { class: 'panel login-page' },
    el('h1', { text: 'Log in to see the plant' }),
    el('p', { class: 'muted', text: 'This HMI does not let visitors look without logging in.' }),
    el('button', { type: 'button', class: 'btn', text: 'Log in', onclick: login }),
  ));
}

async function loadBanners() {
  const slot = clear(document.getElementById('banners'));
  for (const unmount of state.banners) { try { unmount(); } catch { /* ignore */ } }
  state.banners = [];
  for (const module of state.session.banners || []) {
    try {
      const banner = await import(module);
      const node = el('div');
      slot.append(node);
      const unmount = await banner.mount(node, context({}));
      if (unmount) state.banners.push(unmount);
    } catch (error) {
      console.error('banner', module, error);
    }
  }
}

function showNotLive() {
  document.body.classList.remove('offline');
  document.getElementById('offline').hidden = true;
  const connection = document.getElementById('connection');
  connection.className = 'chip conn idle';
  setText(connection, 'not live');
  connection.title = 'Live values begin once you log in';
  document.getElementById('runtime-state').hidden = true;
}

/** The header's runtime state: "unreachable" (greyed) while no fresh value of it can come. */
function showRuntimeState(chip) {
  chip.hidden = false;
  if (document.body.classList.contains('offline')) {
    chip.className = 'chip idle';
    setText(chip, 'unreachable');
    chip.title = 'The runtime cannot be reached: its state is unknown';
    return;
  }
  const item = state.live.get('_sys.state');
  const error = state.live.get('_sys.error');
  const value = item ? String(item.v) : '…';
  chip.className = `chip ${value === 'RUNNING' ? 'ok' : value === 'ERROR' ? 'bad' : 'warn'}`;
  setText(chip, value);
  chip.title = error && error.v ? `Runtime error: ${error.v}` : 'Runtime state';
}

function watchHeader() {
  const chip = document.getElementById('runtime-state');
  const offline = document.getElementById('offline');
  const connection = document.getElementById('connection');
  let countdown = null;
  let last = null;  // the live channel's latest state event
  // Shown once the session is known: a socket refused before it (a login page) is no outage.
  state.showConnection = () => {
    if (!last || !state.booted || (state.session && state.session.login_required)) return;
    const { state: now, reason, retryIn } = last;
    clearInterval(countdown);
    connection.title = '';
    if (now === 'live') {
      connection.className = 'chip conn ok';
      setText(connection, 'live');
      offline.hidden = true;
    } else if (now === 'stopped') {  // closed on purpose (the login page): nothing is wrong
      connection.className = 'chip conn';
      setText(connection, 'not connected');
      offline.hidden = true;
    } else if (now === 'connecting') {
      connection.className = 'chip conn warn';
      setText(connection, 'connecting…');
    } else {
      // Every value shown is stale from now until a fresh snapshot arrives (the 'synced' event
      // below), through all the reconnection attempts: the page greys them (body.offline).
      document.body.classList.add('offline');
      showRuntimeState(chip);
      connection.className = 'chip conn bad';
      setText(connection, 'disconnected');
      offline.hidden = false;
      let left = Math.ceil(retryIn || 0);
      const say = () => setText(offline, `Disconnected from the runtime (${reason}). The values shown are not live. Reconnecting${left > 0 ? ` in ${left} s` : ''}…`);
      say();
      countdown = setInterval(() => { left -= 1; say(); if (left <= 0) clearInterval(countdown); }, 1000);
    }
  };
  state.live.addEventListener('state', (event) => { last = event.detail; state.showConnection(); });
  state.live.addEventListener('synced', () => {
    document.body.classList.remove('offline');
    showRuntimeState(chip);
  });
  state.live.addEventListener('hello', async (event) => {
    // A new runtime (new sessions, maybe new tags), or the first page load found it down.
    if (event.detail.restarted || state.failed) await restart();
  });
  state.live.watch(['_sys.state', '_sys.error'], () => showRuntimeState(chip));
}

async function start() {
  const session = await loadSession();
  renderUser();
  if (session.login_required) {
    // The live channel, opened at once to save time, is refused before a login (401): that is
    // no lost connection. It opens again after the login (restart → reconnect).
    state.live.stop();
    showLoginPage();
    return;
  }
  renderNav();
  await loadBanners();
  route();
}

async function boot() {
  state.live = new Live();
  watchHeader();
  window.addEventListener('hashchange', () => { if (state.session && !state.session.login_required) route(); });
  state.live.connect();  // at once: the socket opens while the session and the page load
  try {
    await start();
  } catch (error) {
    state.failed = true;
    const root = clear(document.getElementById('page'));
    root.append(el('div', { class: 'error-banner', role: 'alert', text: `The runtime cannot be reached: ${error.message}. It reconnects by itself.` }));
  }
  state.booted = true;
  state.showConnection();
  window.softplcHmi = state;  // for debugging and tests: the live channel and session
}

boot();
