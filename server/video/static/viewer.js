// A minimal WHEP viewer page for Aerobase (frontend_api.md, "Live video"); the client itself is
// ./whep.js, which the operator console imports too.
// Open /video/viewer#asset=<asset id>&token=<bearer token>; the fragment never leaves the browser.
// State for pages and tests: window.aerobaseViewer = {state, frames, width, height, error}.

import { watch } from "./whep.js";

const params = new URLSearchParams(location.hash.slice(1));
const asset = params.get("asset");
const token = params.get("token");
const video = document.getElementById("video");
const stateEl = document.getElementById("state");
const infoEl = document.getElementById("info");

function show(state, info = "") {
  stateEl.dataset.state = state;
  stateEl.textContent = state;
  if (info) infoEl.textContent = info;
}

if (!asset || !token) {
  window.aerobaseViewer = { state: "error", frames: 0, width: 0, height: 0, error: "no asset or token" };
  show("error", "open this page as /video/viewer#asset=<asset id>&token=<bearer token>");
} else {
  const w = watch({ asset, video, token: () => token, onState: show });
  window.aerobaseViewer = w.stats;
  addEventListener("pagehide", () => w.stop());
}
