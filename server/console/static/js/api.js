// The REST client: the bearer token, one error shape, and what a dead session means.

const KEY = "aerobase.session";
let session = JSON.parse(sessionStorage.getItem(KEY) || "null");
const listeners = new Set();

export class ApiError extends Error {
  constructor(status, code, message, details) {
    super(message);
    this.status = status;
    this.code = code;
    this.details = details;
  }
}

export const ENDED = {
  session_ended: "Your session ended: another login took this session over, or it was logged out " +
    "(one live session per account). Sign in again to continue here.",
  session_expired: "Your session expired. Sign in again.",
  unauthorized: "You are signed out. Sign in again.",
  account_disabled: "Your account was disabled in this organisation.",
};

// what to tell the person whose session the server ended, in the server's words
export function endedBecause(error) {
  if (error.code !== "session_ended") return ENDED[error.code] || ENDED.unauthorized;
  const why = (error.message || "").replace(/^session ended: /, "");
  if (!why) return ENDED.session_ended;
  const rule = /another login/.test(why)
    ? " Aerobase allows one live session per account: signing in here again ends the other one."
    : "";
  return `Your session ended: ${why}.${rule}`;
}

export function token() { return session && session.token; }
export function current() { return session; }

export function setSession(value) {
  session = value;
  if (value) sessionStorage.setItem(KEY, JSON.stringify(value));
  else sessionStorage.removeItem(KEY);
}

// called with a reason when the server says the session is over
export function onSignedOut(fn) { listeners.add(fn); }
export function signedOut(reason) {
  if (!session) return;
  setSession(null);
  for (const fn of listeners) fn(reason);
}

export async function api(method, path, body, { raw = false, contentType, headers = {} } = {}) {
  const init = { method, headers: { ...headers } };
  const used = token();
  if (used) init.headers.Authorization = `Bearer ${used}`;
  if (body !== undefined) {
    if (contentType) {
      init.headers["Content-Type"] = contentType;
      init.body = body;
    } else {
      init.headers["Content-Type"] = "application/json";
      init.body = JSON.stringify(body);
    }
  }
  let r;
  try {
    r = await fetch(`/api/v1${path}`, init);
  } catch (err) {
    throw new ApiError(0, "network", "the server cannot be reached", null);
  }
  if (r.ok) {
    if (raw) return r;
    if (r.status === 204) return null;
    return r.json();
  }
  let error = { code: "error", message: r.statusText, details: null };
  try { error = (await r.json()).error || error; } catch (_) { /* not JSON */ }
  if (r.status === 401 && path !== "/auth/login") {
    // a request that left with the token a renewal has just replaced is sent again with the new one
    await renewed();
    if (token() && used !== token()) return api(method, path, body, { raw, contentType, headers });
    signedOut(endedBecause(error));
  }
  throw new ApiError(r.status, error.code, error.message, error.details);
}

// a new token for the same session before it expires; the server then closes the sockets opened
// with the old token (4001), which reconnect with the new one once this has finished
let renewal = null;
export function renew() {
  renewal = renewal || api("POST", "/auth/renew").then((r) => {
    setSession({ ...session, token: r.access_token, expires_at: r.expires_at, issued_at: Date.now() });
  }).finally(() => { renewal = null; });
  return renewal;
}
export function renewed() { return renewal ? renewal.catch(() => {}) : Promise.resolve(); }

export const get = (path) => api("GET", path);
export const post = (path, body) => api("POST", path, body);
