// The WHEP client of Aerobase (frontend_api.md, "Live video"), shared by the viewer page
// (/video/viewer) and the operator console: one module, served at /video/whep.js. No dependencies.
//
//   const w = watch({ asset, video, token: () => bearer, onState: (state, info) => ... });
//   w.stop();  // ends the session (DELETE on its Location)
//
// States: "starting", "connecting" (negotiated, the asset live, no frame yet), "no signal" (the
// asset publishes nothing; the session stays and its first frame turns it live), "live",
// "reconnecting" (frames stopped, or the peer connection failed: a new session is negotiated when
// the asset is live but nothing reaches us), "error" (the server refused; retried after
// Retry-After for 503/409).
// w.stats: {state, frames, width, height, error, info} — frames counts requestVideoFrameCallback.
//
// openWhenLive (a page showing many UAVs, e.g. the console's fleet): no session is held for an
// asset that publishes nothing. Nothing happens until w.wake(); then the description is read and a
// session opened only when the asset is live, else "no signal" with no session. Call w.wake() when
// the asset's video goes live (`video_state` on /ws/operator) and after that socket reconnects.
// A session whose asset stops publishing is ended (the description says so), not kept.
// w.sleep() ends the session and holds none until the next w.wake() (a panel off the screen).

const STALL_MS = 2000; // no frame for this long: "reconnecting"
const GIVE_UP_MS = 10000; // still none: ask the server whether the asset publishes

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

export function watch({ asset, video, token, onState = () => {}, openWhenLive = false }) {
  const stats = { state: "starting", frames: 0, width: 0, height: 0, error: null, info: "" };
  let session = null; // {pc, location}
  let stopped = false;
  let lastFrameAt = 0;
  let checking = false;
  let nextCheckAt = 0;
  let backoff = 500; // ms before the next attempt when the server cannot be reached
  let trying = false; // an attempt, or its scheduled retry, is under way
  let again = false; // woken during an attempt: look once more when it ends without a session
  let asleep = false; // put to sleep: no session until woken

  const show = (state, info) => {
    if (info !== undefined) stats.info = info;
    if (state === stats.state && info === undefined) return;
    stats.state = state;
    onState(state, stats.info);
  };
  const api = (path, init = {}) =>
    fetch(path, { ...init, headers: { ...(init.headers || {}), Authorization: `Bearer ${token()}` } });
  const describe = async () => {
    const described = await api(`/api/v1/assets/${encodeURIComponent(asset)}/video`);
    if (!described.ok) {
      const err = new Error(await errorOf(described));
      err.status = described.status;
      throw err;
    }
    return described.json();
  };

  async function post(pc, url, sdp) {
    const answered = await api(url, {
      method: "POST", body: sdp, headers: { "Content-Type": "application/sdp" },
    });
    if (!answered.ok) {
      pc.close();
      const retry = Number(answered.headers.get("Retry-After") || 0);
      const err = new Error(await errorOf(answered));
      err.retryAfterS = answered.status === 503 || answered.status === 409 ? Math.max(1, retry || 2) : 0;
      err.status = answered.status;
      throw err;
    }
    return answered;
  }

  function end() {
    if (!session) return;
    const { pc, location: where } = session;
    session = null;
    pc.close();
    if (where) api(where, { method: "DELETE" }).catch(() => {});
  }

  async function connect() {
    const desc = await describe();
    const info = `${desc.width}×${desc.height} ${desc.codec} @ ${desc.fps} fps · ${desc.path}`;
    if (openWhenLive && desc.state !== "live") {
      show("no signal", info); // no session until the asset publishes (wake)
      return;
    }
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
    if (stopped || asleep) { end(); return; }
    pc.addEventListener("connectionstatechange", () => {
      if (["failed", "closed"].includes(pc.connectionState) && session && session.pc === pc && !stopped && !asleep) {
        show("reconnecting");
        end();
        start(1000);
      }
    });
    lastFrameAt = performance.now();
    show(desc.state === "live" ? "connecting" : "no signal", info);
  }

  async function start(delayMs = 0) {
    trying = true;
    if (delayMs) await new Promise((r) => setTimeout(r, delayMs));
    if (stopped) return;
    if (asleep) { trying = false; return; }
    try {
      await connect();
    } catch (err) {
      if (stopped) return;
      if (asleep) { trying = false; return; } // put to sleep mid-attempt (its session ended)
      end();
      stats.error = String(err.message || err);
      if (err.retryAfterS) {
        show("error", stats.error);
        start(err.retryAfterS * 1000);
        return;
      } else if (err.status === undefined || err.status >= 500 || err.status === 401) {
        // the server is away (restart, a replica's death) or the token was being renewed: again,
        // backing off to 8 s; a refusal (404 no video, 403) stays an error
        show("reconnecting");
        backoff = Math.min(8000, backoff * 2);
        start(backoff);
        return;
      }
      show("error", stats.error); // refused: stays an error
      trying = false;
      return;
    }
    backoff = 500;
    stats.error = null;
    trying = false;
    if (again && !session && !stopped && !asleep) {
      again = false;
      start();
    }
  }

  function wake() {
    if (stopped) return;
    asleep = false;
    if (session) return;
    if (trying) again = true;
    else start();
  }

  function sleep() {
    if (stopped || asleep) return;
    asleep = true;
    again = false;
    end();
    video.srcObject = null;
    show("paused");
  }

  function onFrame(_now, meta) {
    if (stopped) return;
    if (!session) {
      // a frame presented as a closed session's track ends is no sign of life
      video.requestVideoFrameCallback(onFrame);
      return;
    }
    stats.frames = meta.presentedFrames;
    stats.width = meta.width;
    stats.height = meta.height;
    lastFrameAt = performance.now();
    if (stats.state !== "live") show("live");
    video.requestVideoFrameCallback(onFrame);
  }
  video.requestVideoFrameCallback(onFrame);

  // frames stopped after some came: "reconnecting" at once (the asset's link or ours is down and
  // its next frames reach this session); still nothing after GIVE_UP_MS: the description says
  // whether the asset publishes at all ("no signal") or our session is dead (a new one)
  const timer = setInterval(async () => {
    const quiet = performance.now() - lastFrameAt;
    if (stopped || checking || !session || quiet < STALL_MS) return;
    if (stats.state === "live") { show("reconnecting"); return; }
    if (!["reconnecting", "no signal"].includes(stats.state) || quiet < GIVE_UP_MS) return;
    if (performance.now() < nextCheckAt) return;
    nextCheckAt = performance.now() + GIVE_UP_MS / 2;
    checking = true;
    try {
      const desc = await describe();
      if (stopped || asleep) return;
      if (desc.state !== "live") {
        if (openWhenLive) {
          end(); // its next publication wakes us
          video.srcObject = null; // no frozen last frame under "no signal"
        }
        show("no signal");
      } else {
        show("reconnecting");
        end();
        await start();
      }
    } catch {
      // the server is away: the next tick looks again
    } finally {
      checking = false;
    }
  }, 500);

  if (!openWhenLive) start();
  return {
    stats,
    wake,
    sleep,
    stop() {
      stopped = true;
      clearInterval(timer);
      end();
    },
  };
}
