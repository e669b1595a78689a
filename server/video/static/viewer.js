// A minimal WHEP viewer for Aerobase (frontend_api.md, "Live video"). No dependencies.
// Open /video/viewer#asset=<asset id>&token=<bearer token>; the fragment never leaves the browser.
// State for pages and tests: window.aerobaseViewer = {state, frames, width, height, error}.

const params = new URLSearchParams(location.hash.slice(1));
const asset = params.get("asset");
const token = params.get("token");
const video = document.getElementById("video");
const stateEl = document.getElementById("state");
const infoEl = document.getElementById("info");
const viewer = (window.aerobaseViewer = { state: "starting", frames: 0, width: 0, height: 0, error: null });
const STALL_MS = 2000; // no frame for this long: the drone's link is down, show "reconnecting"

function show(state, info = "") {
  viewer.state = state;
  stateEl.dataset.state = state;
  stateEl.textContent = state;
  if (info) infoEl.textContent = info;
}

async function api(path, init = {}) {
  const headers = { ...(init.headers || {}), Authorization: `Bearer ${token}` };
  return fetch(path, { ...init, headers });
}

async function errorOf(response) {
  try {
    const body = await response.json();
    return `${response.status} ${body.error.code}: ${body.error.message}`;
  } catch {
    return `${response.status}`;
  }
}

function gathered(pc, timeoutMs) {
  if (pc.iceGatheringState === "complete") return Promise.resolve();
  return new Promise((resolve) => {
    const done = () => { if (pc.iceGatheringState === "complete") resolve(); };
    pc.addEventListener("icegatheringstatechange", done);
    setTimeout(resolve, timeoutMs);
  });
}

let session = null; // {pc, location}

async function post(pc, url, sdp) {
  const answered = await api(url, {
    method: "POST", body: sdp, headers: { "Content-Type": "application/sdp" },
  });
  if (!answered.ok) {
    pc.close();
    const retry = Number(answered.headers.get("Retry-After") || 0);
    const err = new Error(await errorOf(answered));
    err.retryAfterS = answered.status === 503 || answered.status === 409 ? Math.max(1, retry || 2) : 0;
    throw err;
  }
  return answered;
}

async function stop() {
  if (!session) return;
  const { pc, location: where } = session;
  session = null;
  pc.close();
  if (where) api(where, { method: "DELETE" }).catch(() => {});
}

async function connect() {
  const described = await api(`/api/v1/assets/${encodeURIComponent(asset)}/video`);
  if (!described.ok) throw new Error(await errorOf(described));
  const desc = await described.json();
  infoEl.textContent = `${desc.width}×${desc.height} ${desc.codec} @ ${desc.fps} fps · ${desc.path}`;
  const iceServers = desc.ice_servers.map((s) => ({
    urls: s.urls, ...(s.username ? { username: s.username, credential: s.credential } : {}),
  }));
  const pc = new RTCPeerConnection({ iceServers });
  pc.ontrack = (event) => { video.srcObject = event.streams[0] || new MediaStream([event.track]); };
  if (desc.viewer_offers) {
    // WHEP (RFC 9725): we offer, the server answers
    pc.addTransceiver("video", { direction: "recvonly" });
    await pc.setLocalDescription(await pc.createOffer());
    await gathered(pc, 2000);
    const answered = await post(pc, desc.whep_url, pc.localDescription.sdp);
    session = { pc, location: answered.headers.get("Location") };
    await pc.setRemoteDescription({ type: "answer", sdp: await answered.text() });
  } else {
    // the Janus path: the gateway offers (empty POST), we answer with PATCH
    const offered = await post(pc, desc.whep_url, "");
    session = { pc, location: offered.headers.get("Location") };
    await pc.setRemoteDescription({ type: "offer", sdp: await offered.text() });
    await pc.setLocalDescription(await pc.createAnswer());
    await gathered(pc, 2000);
    const patched = await api(session.location, {
      method: "PATCH", body: pc.localDescription.sdp, headers: { "Content-Type": "application/sdp" },
    });
    if (!patched.ok) throw new Error(await errorOf(patched));
  }
  pc.addEventListener("connectionstatechange", () => {
    if (["failed", "closed"].includes(pc.connectionState) && session && session.pc === pc) {
      show("reconnecting");
      stop().then(() => start(1000));
    }
  });
  show(desc.state === "live" ? "connecting" : "waiting");
}

async function start(delayMs = 0) {
  if (delayMs) await new Promise((r) => setTimeout(r, delayMs));
  try {
    await connect();
  } catch (err) {
    viewer.error = String(err.message || err);
    show("error", viewer.error);
    if (err.retryAfterS) start(err.retryAfterS * 1000);
  }
}

let lastFrameAt = 0;
function onFrame(_now, meta) {
  viewer.frames = meta.presentedFrames;
  viewer.width = meta.width;
  viewer.height = meta.height;
  lastFrameAt = performance.now();
  if (viewer.state !== "live") show("live");
  video.requestVideoFrameCallback(onFrame);
}
video.requestVideoFrameCallback(onFrame);
setInterval(() => {
  if (viewer.state === "live" && performance.now() - lastFrameAt > STALL_MS) show("reconnecting");
}, 500);
addEventListener("pagehide", stop);

if (!asset || !token) {
  show("error", "open this page as /video/viewer#asset=<asset id>&token=<bearer token>");
} else {
  start();
}
