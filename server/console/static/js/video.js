// The UAV's live camera on the fleet page, through the WHEP client the video viewer page uses too
// (/video/whep.js, served by server/video: one client, not two). Viewers may watch: video is not
// a control. The panel's state is a status (live, no signal, reconnecting); the frames decoded so
// far are the video's data-frames (requestVideoFrameCallback's count).

import { token } from "./api.js";
import { h } from "./ui.js";

const SAY = {
  starting: ["starting…", "warn"],
  connecting: ["connecting…", "warn"],
  "no signal": ["no signal (the UAV is not sending video)", "warn"],
  live: ["live", "ok"],
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
  const onState = (state, detail) => {
    const [text, tone] = SAY[state] || [state, ""];
    status.textContent = state === "error" ? `${text}: ${detail}` : text;
    status.dataset.state = state;
    status.className = `video-state ${tone}`;
    info.textContent = state === "error" ? "" : detail ? ` · ${detail}` : "";
  };
  import("/video/whep.js").then(({ watch }) => {
    if (stopped) return;
    watching = watch({ asset: asset.id, video, token, onState });
    const copy = (_now, meta) => {
      if (stopped) return;
      video.dataset.frames = String(meta.presentedFrames);
      video.requestVideoFrameCallback(copy);
    };
    video.requestVideoFrameCallback(copy);
  }).catch((err) => onState("error", `the video client did not load (${err.message})`));
  return { el, stop() { stopped = true; if (watching) watching.stop(); } };
}
