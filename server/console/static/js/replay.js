// Replay: a time slider over a past run's stored telemetry; the track, the base's state and the
// run's step move together.

import { get } from "./api.js";
import { loadFlight } from "./flight.js";
import { missionPoints } from "./geo.js";
import { lineChart, trackMap } from "./plot.js";
import { STEPS } from "./runs.js";
import { clear, h, num } from "./ui.js";
import { recordedPanel } from "./video.js";

function before(rows, t) {
  let lo = 0, hi = rows.length - 1, found = null;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (rows[mid].t <= t) { found = rows[mid]; lo = mid + 1; } else hi = mid - 1;
  }
  return found;
}

export function render(main, ctx, args) {
  let recorded = null; // the run's recorded video (one element; the slider seeks it)
  const box = h("div", {}, h("p", {}, "Loading the run's telemetry…"));
  clear(main, h("h1", {}, "Replay"), box);
  (async () => {
    const f = await loadFlight(ctx, args[0]);
    const { run, track, t0, t1 } = f;
    const window = `start=${encodeURIComponent(run.created_at)}&end=${encodeURIComponent(new Date(t1).toISOString())}&limit=100000`;
    const baseRows = (await get(`/assets/${run.base_id}/telemetry?${window}&fields=panels.state,panels.position_pct,lift.state,lift.position_pct,uav_present,scale_mass_g,charger.state`))
      .map((r) => ({ ...r, t: Date.parse(r.ts) }));
    const steps = (run.timeline || []).map((x) => ({ ...x, t: Date.parse(x.at) }));
    const label = Object.fromEntries(STEPS);
    const slider = h("input", { id: "replay-time", type: "range", min: 0, max: Math.max(1, Math.round((t1 - t0) / 1000)), step: 0.5, value: 0 });
    const readout = h("output", { for: "replay-time", id: "replay-readout" });
    const left = h("div");
    const now = h("div"); // the state at the slider's moment, redrawn; the video below it stays
    const view = h("div", { class: "cols" });
    const mission = f.mission && f.origin ? missionPoints(f.mission, f.origin) : [];
    recorded = recordedPanel(run.uav_id, t0, t1);
    const draw = () => {
      const t = t0 + Number(slider.value) * 1000;
      const p = before(track, t);
      const b = before(baseRows, t);
      const s = before(steps, t);
      readout.textContent = `${Number(slider.value).toFixed(1)} s into the run`;
      const shown = track.filter((x) => x.t <= t);
      clear(left, f.origin ? trackMap({ title: "Track until this moment", track: shown, mission, uav: p && Number.isFinite(p.north) ? p : null, geo: f.origin }) : null);
      clear(now,
        h("dl", { class: "kv", "aria-label": "State at this moment" },
          h("dt", {}, "Run step"), h("dd", {}, s ? `${s.to_state}${label[s.to_state] ? ` — ${label[s.to_state]}` : ""}` : "pending"),
          h("dt", {}, "Reason"), h("dd", {}, s ? s.reason : "–"),
          h("dt", {}, "UAV altitude"), h("dd", {}, p ? num(p["position.alt_rel_m"], 1, "m") : "–"),
          h("dt", {}, "UAV battery"), h("dd", {}, p ? num(p["battery.percent"], 0, "%") : "–"),
          h("dt", {}, "Base panels"), h("dd", {}, b && b["panels.state"] ? `${b["panels.state"]} ${num(b["panels.position_pct"], 0, "%")}` : "–"),
          h("dt", {}, "Base lift"), h("dd", {}, b && b["lift.state"] ? `${b["lift.state"]} ${num(b["lift.position_pct"], 0, "%")}` : "–"),
          h("dt", {}, "UAV on the scale"), h("dd", {}, b && b.uav_present !== undefined ? `${b.uav_present ? "yes" : "no"} ${num(b.scale_mass_g, 0, "g")}` : "–"),
          h("dt", {}, "Charger"), h("dd", {}, b && b["charger.state"] ? b["charger.state"] : "–")),
          lineChart({ title: "Altitude", unit: "m", points: track.map((x) => ({ t: x.t, v: x["position.alt_rel_m"] })), t0, t1, cursor: t }));
      recorded.seek(t);
    };
    slider.addEventListener("input", draw);
    clear(box,
      h("div", { class: "field" }, h("label", { for: "replay-time" }, "Time in the run"), slider, readout),
      clear(view, left, h("div", {}, now, recorded.el)));
    draw();
  })().catch((err) => clear(box, h("p", { role: "alert", class: "error" }, `The replay could not be loaded: ${err.message}`)));
  return () => { if (recorded) recorded.stop(); };
}
