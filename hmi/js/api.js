// The JSON API (docs/hmi.md): every request carries the session cookie; state-changing ones
// also carry the session's CSRF token in X-CSRF-Token.

let csrf = null;

export function setCsrf(token) { csrf = token; }

export class ApiError extends Error {
  constructor(status, body) {
    super((body && body.error) || `HTTP ${status}`);
    this.status = status;
    this.body = body;
  }
}

async function request(method, path, body) {
  const headers = { 'Accept': 'application/json' };
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  if (method !== 'GET' && csrf) headers['X-CSRF-Token'] = csrf;
  const response = await fetch(path, {
    method, headers, credentials: 'same-origin', cache: 'no-store',
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  let data = null;
  try { data = await response.json(); } catch { data = null; }
  if (!response.ok && !(data && Array.isArray(data.results))) throw new ApiError(response.status, data);
  return { status: response.status, data };
}

export async function get(path) { return (await request('GET', path)).data; }
export async function post(path, body) { return (await request('POST', path, body)).data; }

/** Write one tag: {ok, results: [{tag, ok, rule, detail, old, value}]}; never throws for a refusal. */
export async function writeTag(tag, value) {
  const { data } = await request('POST', '/api/write', { tag, value });
  return data;
}

/** Declarations (unit, range, writable...) of tags, cached per session; `names` or all. */
const metaCache = new Map();
let allLoaded = null;

export function forgetMeta() { metaCache.clear(); allLoaded = null; }

export async function tagMeta(names) {
  const missing = names.filter((name) => !metaCache.has(name) && !name.startsWith('='));
  if (missing.length) {
    for (let i = 0; i < missing.length; i += 500) {
      const chunk = missing.slice(i, i + 500);
      const data = await get(`/api/tags?names=${encodeURIComponent(chunk.join(','))}`);
      for (const tag of data.tags) metaCache.set(tag.name, tag);
    }
  }
  return names.map((name) => metaCache.get(name)).filter(Boolean);
}

export async function allTagMeta() {
  if (!allLoaded) {
    allLoaded = get('/api/tags').then((data) => {
      for (const tag of data.tags) metaCache.set(tag.name, tag);
      return data.tags;
    });
    allLoaded.catch(() => { allLoaded = null; });
  }
  return allLoaded;
}

export async function tagsWithPrefix(prefix) {
  const data = await get(`/api/tags?prefix=${encodeURIComponent(prefix)}`);
  for (const tag of data.tags) metaCache.set(tag.name, tag);
  return data.tags;
}
