// The UAV's live camera on the fleet page, through the WHEP client the video viewer page uses too
// (/video/whep.js, served by server/video: one client, not two). Viewers may watch: video is not
// a control. The panel's state is a status (live, no signal, reconnecting); the frames decoded so
// far are the video's data-frames (requestVideoFrameCallback's count).
//
// A fleet page shows every UAV, most of them idle: a panel holds a viewer session only while its
// UAV publishes. It reads the description once the operator socket is up (and after each of its
// reconnects) and opens a session when the UAV is live; the server's `video_state` message on
// that socket says when an idle UAV starts publishing. No panel asks again and again. A panel
// whose card is off the screen holds no session either ("paused"), so a fleet page takes a
// viewer place (AEROBASE_VIDEO_MAX_VIEWERS per UAV) only for the UAVs it shows.

import { api, get, token } from "./api.js";
import { on, state as feed } from "./live.js";
import { h } from "./ui.js";

const SAY = {
  starting: ["starting…", "warn"],
  connecting: ["connecting…", "warn"],
  "no signal": ["no signal (the UAV is not sending video)", "warn"],
  live: ["live", "ok"],
  paused: ["paused (off screen)", ""],
  reconnecting: ["reconnecting…", "warn"],
  error: ["unavailable", "bad"],
};

export function livePanel(asset) {
  const video = h("video", { "aria-label": `Live video of ${asset.name}`, playsinline: true, "data-frames": "0" });
  video.muted = true;
  video.autoplay = true;
  const status = h("p", { role: "status", "aria-live": "polite", "aria-label": `Video state of ${asset.name}`, class: "video-state" }, "starting…");
  const info = h("span", { class: "muted" });
  const el = h("figure", { class: "video" }, video, h("figcaption", {}, status, info));
  let watching = null;
  let stopped = false;
  let offs = [];
  let onScreen = true; // the fleet page says when its card leaves the screen (shown)
  const onState = (state, detail) => {
    const [text, tone] = SAY[state] || [state, ""];
    status.textContent = state === "error" ? `${text}: ${detail}` : text;
    status.dataset.state = state;
    status.className = `video-state ${tone}`;
    info.textContent = state === "error" ? "" : detail ? ` · ${detail}` : "";
  };
  import("/video/whep.js").then(({ watch }) => {
    if (stopped) return;
    watching = watch({ asset: asset.id, video, token, onState, openWhenLive: true });
    const w = watching;
    offs = [
      on("video_state", (p) => { if (p.asset_id === asset.id && p.state === "live" && onScreen) w.wake(); }),
      on("reconnected", () => { if (onScreen) w.wake(); }),
    ];
    if (!onScreen) w.sleep(); // its card left the screen before this module loaded
    else if (feed.link === "live") w.wake(); // the socket opened before this module loaded
    const copy = (_now, meta) => {
      if (stopped) return;
      video.dataset.frames = String(meta.presentedFrames);
      video.requestVideoFrameCallback(copy);
    };
    video.requestVideoFrameCallback(copy);
  }).catch((err) => onState("error", `the video client did not load (${err.message})`));
  return {
    el,
    // on the screen (or near it) the panel watches; off it, it holds no session
    shown(visible) {
      if (visible === onScreen) return;
      onScreen = visible;
      if (!watching) return;
      if (!visible) watching.sleep();
      else if (feed.link === "live") watching.wake();
    },
    stop() {
      stopped = true;
      for (const off of offs) off();
      if (watching) watching.stop();
    },
  };
}

// The run's recorded video on the replay page: the UAV's WebM segments (newest first from the
// API), the one holding the slider's moment fetched with the bearer token and played from a blob:
// URL, positioned by its frame-times file (server clock → the segment's 90 kHz timestamps).
// When the server records nothing of the run, it says so.
const PAGE = 1000;

async function segmentsOf(uavId, t0) {
  const found = [];
  for (let offset = 0; ; offset += PAGE) {
    const rows = await get(`/assets/${uavId}/video/recordings?limit=${PAGE}&offset=${offset}`);
    found.push(...rows.map((r) => ({ ...r, t: Date.parse(r.started_at) })));
    // newest first: stop at the first segment begun before the run (it may hold its start)
    if (rows.length < PAGE || found[found.length - 1].t <= t0) break;
  }
  return found.sort((a, b) => a.t - b.t);
}

async function download(url) {
  return api("GET", url.replace(/^\/api\/v1/, ""), undefined, { raw: true });
}

export function recordedPanel(uavId, t0, t1) {
  const video = h("video", { "aria-label": "Recorded video of the run", playsinline: true, preload: "auto" });
  video.muted = true;
  const status = h("p", { role: "status", "aria-live": "polite", "aria-label": "Recorded video state", class: "video-state" }, "looking for a recording…");
  const el = h("figure", { class: "video" }, video, h("figcaption", {}, status));
  video.hidden = true;
  const say = (text, tone = "", playing = false) => {
    status.textContent = text;
    status.className = `video-state ${tone}`;
    video.hidden = !playing;
  };
  const loaded = new Map(); // segment name -> Promise<{url, times}>
  let segments = null;
  let wanted = null;
  const ready = segmentsOf(uavId, t0).then((all) => {
    segments = all.filter((s, i) => s.t <= t1 && (i + 1 === all.length || all[i + 1].t > t0));
    if (!segments.length) say("no recording of this run (the server recorded no video of this UAV then)");
  }).catch((err) => {
    segments = [];
    say(err.code === "video_disabled" ? "no recording: live video is off on this server" : `no recording: ${err.message}`);
  });
  const load = (s) => {
    if (!loaded.has(s.name)) {
      loaded.set(s.name, (async () => {
        const [blob, text] = await Promise.all([
          download(s.url).then((r) => r.blob()),
          download(s.times_url).then((r) => r.text()),
        ]);
        // (a segment still being written may end in a half-written line: it is left out)
        const times = text.split("\n").flatMap((line) => { try { return [JSON.parse(line)]; } catch { return []; } });
        return { url: URL.createObjectURL(blob), times };
      })());
    }
    return loaded.get(s.name);
  };
  let shownUrl = null;
  let pending = null;
  video.addEventListener("loadedmetadata", () => {
    if (pending !== null) video.currentTime = pending;
    pending = null;
  });
  const seek = async (t) => {
    wanted = t;
    await ready;
    if (!segments.length || wanted !== t) return;
    let s = null;
    for (const x of segments) if (x.t <= t + 500) s = x;
    if (!s) return say("not recorded at this moment", "warn");
    let seg;
    try { seg = await load(s); } catch (err) { return say(`the recording could not be loaded: ${err.message}`, "bad"); }
    if (wanted !== t) return;
    const { times } = seg;
    if (!times.length || t > times[times.length - 1].t + 1000) {
      // the newest segment may still be growing: read it again next time
      if (s === segments[segments.length - 1]) loaded.delete(s.name);
      return say("not in the recording at this moment", "warn");
    }
    let frame = times[0];
    for (const x of times) { if (x.t > t) break; frame = x; }
    if (shownUrl !== seg.url) { video.src = seg.url; shownUrl = seg.url; }
    // the frame's place in the segment (its 90 kHz pts); before the metadata, once they are read
    if (video.readyState >= 1) video.currentTime = frame.pts / 90000;
    else pending = frame.pts / 90000;
    say(`recorded · ${s.name}`, "ok", true);
  };
  return {
    el, seek,
    stop() { for (const p of loaded.values()) p.then((x) => URL.revokeObjectURL(x.url)).catch(() => {}); },
  };
}
