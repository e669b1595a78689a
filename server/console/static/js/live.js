// The /ws/operator socket: subscribe to the organisation's assets, keep the latest state of each,
// reconnect by itself (server restart, a replica's death), and say when the data are stale.

import { ENDED, get, renewed, signedOut, token } from "./api.js";
import { flatten } from "./ui.js";

export const STALE_MS = 5000; // UAVs report at 5 Hz, bases at 1-5 Hz: 5 s of silence is stale

export const state = {
  telemetry: new Map(), // asset id -> {values (dotted names), at (ms, received)}
  availability: new Map(), // asset id -> {available, failed, conditions, at, status, reason}
  events: [], // newest first, at most 50
  link: "offline", // "connecting" | "live" | "reconnecting" | "offline"
  retryIn: 0,
};

const handlers = new Map(); // message type -> Set of functions
export function on(type, fn) {
  if (!handlers.has(type)) handlers.set(type, new Set());
  handlers.get(type).add(fn);
  return () => handlers.get(type).delete(fn);
}
function emit(type, payload, msg) {
  for (const fn of handlers.get(type) || []) {
    try { fn(payload, msg); } catch (err) { console.error(err); }
  }
}

let socket = null;
let ids = [];
let attempt = 0;
let timer = null;
let seq = 0;
let wanted = false;

function envelope(type, payload) {
  return JSON.stringify({ v: 1, type, id: crypto.randomUUID(), seq: seq++, ts: Date.now(), payload });
}

function setLink(link, retryIn = 0) {
  state.link = link;
  state.retryIn = retryIn;
  emit("link", link);
}

export function follow(assetIds) {
  ids = [...assetIds];
  wanted = true;
  if (socket && socket.readyState === WebSocket.OPEN) {
    socket.send(envelope("subscribe", { asset_ids: ids }));
  } else if (!socket) {
    open();
  }
}

export function stop() {
  wanted = false;
  clearTimeout(timer);
  if (socket) socket.close(1000);
  socket = null;
  state.telemetry.clear();
  state.availability.clear();
  state.events = [];
  setLink("offline");
  emit("stopped");
}

// the outcome of a check_availability (from a run's check or an operator's) is the base's go/no-go
export function noteAvailability(assetId, status, reason, data, at) {
  if (!data || typeof data.available !== "boolean") return;
  state.availability.set(assetId, { ...data, status, reason, at });
  emit("availability", assetId);
}

function open() {
  clearTimeout(timer);
  if (!wanted || !token()) return;
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${scheme}://${location.host}/ws/operator?token=${encodeURIComponent(token())}`);
  socket = ws;
  setLink(attempt ? "reconnecting" : "connecting");
  ws.onopen = () => {
    attempt = 0;
    seq = 0;
    ws.send(envelope("subscribe", { asset_ids: ids }));
    setLink("live");
    emit("reconnected");
  };
  ws.onmessage = (e) => {
    let msg;
    try { msg = JSON.parse(e.data); } catch (_) { return; }
    const p = msg.payload || {};
    if (msg.type === "telemetry") {
      state.telemetry.set(p.asset_id, { values: flatten(p), at: Date.now(), ts: msg.ts });
    } else if (msg.type === "event") {
      state.events.unshift({ ...p, ts: msg.ts });
      state.events.length = Math.min(state.events.length, 50);
    } else if (msg.type === "command_result" && p.data) {
      noteAvailability(p.asset_id, p.status, p.reason, p.data, Date.now());
    }
    emit(msg.type, p, msg);
  };
  ws.onclose = (e) => {
    if (socket !== ws) return;
    socket = null;
    if (e.code === 4001) {
      // ask why: the server's answer to the ended token names the reason (a take-over, a logout)
      // (after our own renewal the new token answers, and the socket reopens with it)
      renewed().then(() => get("/auth/me")).then(() => { if (wanted) open(); }, () => signedOut(ENDED.session_ended));
      return;
    }
    if (e.code === 4401) return signedOut(ENDED.unauthorized);
    if (!wanted) return setLink("offline");
    attempt += 1;
    const wait = Math.min(8000, 500 * 2 ** Math.min(attempt - 1, 4));
    setLink("reconnecting", wait);
    timer = setTimeout(open, wait);
  };
}

// one ticker for "n s ago" labels and stale flags
setInterval(() => emit("tick"), 1000);

export function freshness(assetId) {
  const t = state.telemetry.get(assetId);
  if (!t) return { stale: true, age: null };
  const age = Date.now() - t.at;
  return { stale: age > STALE_MS || state.link !== "live", age };
}
