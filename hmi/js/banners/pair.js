// The redundant pair's banner, on every page of a runtime that is a member of a pair
// (docs/redundancy.md): which runtime is active, this one's role and the pair's health; and it
// follows the active — a page of the standby (or of a runtime that stopped answering) goes to
// the active's HMI, on the same page, after a short countdown the user can cancel.

import { el, setText } from '../dom.js';

const NAMES = ['role', 'member', 'active', 'epoch', 'peer', 'peer_ok', 'degraded', 'active_hmi', 'peer_hmi']
  .map((name) => `_sys.redundancy.${name}`);
const FOLLOW_AFTER = 3;  // s of countdown before the page goes to the active
const LOST_AFTER = 4000;  // ms without this runtime before the page goes to its peer

function value(live, name) {
  const item = live.get(`_sys.redundancy.${name}`);
  return item ? item.v : undefined;
}

function sameHmi(a, b) {
  try { return new URL(a, location.href).origin === new URL(b, location.href).origin; } catch { return false; }
}

export function mount(node, ctx) {
  const live = ctx.live;
  const text = el('span', { class: 'pair-text' });
  const follow = el('span', { class: 'pair-follow' });
  const stay = el('button', { type: 'button', class: 'btn small', text: 'stay here', hidden: true });
  const banner = el('div', { class: 'pair-banner', role: 'status', 'aria-live': 'polite' }, text, follow, stay);
  node.append(banner);
  let target = '';
  let countdown = 0;
  let timer = null;
  let stayed = false;
  let peerHmi = '';
  let lostTimer = null;

  function go(url) {
    location.href = new URL(url, location.href).origin + location.pathname + location.hash;
  }

  function tick() {
    if (!target || stayed) { clearInterval(timer); timer = null; setText(follow, ''); stay.hidden = true; return; }
    if (countdown <= 0) { clearInterval(timer); timer = null; go(target); return; }
    setText(follow, ` — going to the active in ${countdown} s`);
    stay.hidden = false;
    countdown -= 1;
  }

  function followTo(url) {
    if (!url || sameHmi(url, location.href) || stayed) { target = ''; tick(); return; }
    if (target === url && timer) return;
    target = url;
    countdown = FOLLOW_AFTER;
    clearInterval(timer);
    timer = setInterval(tick, 1000);
    tick();
  }

  function draw() {
    const role = value(live, 'role');
    if (role === undefined) return;
    const member = value(live, 'member') || '?';
    const active = value(live, 'active') || '';
    const healthy = value(live, 'peer_ok') && !value(live, 'degraded');
    peerHmi = value(live, 'peer_hmi') || peerHmi;
    banner.className = `pair-banner ${role === 'ACTIVE' ? 'active' : 'standby'} ${healthy ? 'healthy' : 'degraded'}`;
    const who = role === 'ACTIVE' ? `this runtime (${member}) is ACTIVE` : `this runtime (${member}) is ${role}` + (active ? `; the active is ${active}` : '; no active now');
    setText(text, `Redundant pair, epoch ${value(live, 'epoch') ?? '?'}: ${who} · ${healthy ? 'peer in sync' : `degraded: ${value(live, 'peer') || 'peer unknown'}`}`);
    followTo(role !== 'ACTIVE' && active && active !== member ? value(live, 'active_hmi') : '');
  }

  stay.addEventListener('click', () => { stayed = true; tick(); });
  const watcher = live.watch(NAMES, draw);
  const onState = (event) => {
    clearTimeout(lostTimer);
    if (event.detail.state === 'disconnected' && peerHmi && !stayed) {
      // This runtime is gone (killed, its machine down): its peer is the active now, or soon.
      lostTimer = setTimeout(() => followTo(peerHmi), LOST_AFTER);
    }
  };
  live.addEventListener('state', onState);
  draw();
  return () => {
    watcher.close();
    live.removeEventListener('state', onState);
    clearInterval(timer);
    clearTimeout(lostTimer);
  };
}
