// A run's report: figures, the eight steps, plots of altitude, battery, ground speed and the
// distance from the pad during the landing, and the flight track around the base.

import { loadFlight, entered } from "./flight.js";
import { missionPoints } from "./geo.js";
import { lineChart, trackMap } from "./plot.js";
import { outcomeWords, stateBadge, stepList, timelineTable } from "./runs.js";
import { clear, h, num, when } from "./ui.js";

function figure(caption, svg) {
  return h("figure", {}, h("figcaption", {}, caption), svg);
}

export function render(main, ctx, args) {
  const box = h("div", {}, h("p", {}, "Loading the report…"));
  clear(main, h("h1", {}, "Run report"), box);
  (async () => {
    const f = await loadFlight(ctx, args[0]);
    const { report, run, track, t0, t1 } = f;
    const name = (id) => (ctx.byId.get(id) || { name: "?" }).name;
    const marks = ["flying", "landing", "confirming"].map((s) => ({ t: entered(run, s), label: s })).filter((m) => m.t);
    const series = (key) => track.map((p) => ({ t: p.t, v: p[key] }));
    const landing = report.landing;
    // the GNSS track from the landing step to the touchdown the agent reported, ending on the
    // touchdown offset it measured (the headline's figure): one line, the same last value
    const landFrom = entered(run, "landing") ?? t0;
    const touchdown = landing && landing.landed_at ? Date.parse(landing.landed_at) : null;
    const landTo = touchdown ?? entered(run, "confirming") ?? t1;
    const nearPad = track.filter((p) => p.t >= landFrom && p.t < landTo && Number.isFinite(p.north))
      .map((p) => ({ t: p.t, v: Math.hypot(p.north, p.east) }));
    // the GNSS distance is to the base's surveyed position, itself a GNSS fix: when the two
    // disagree at touchdown the page says so rather than leave two figures unexplained
    const lastGnss = nearPad.length ? nearPad[nearPad.length - 1].v : null;
    const measured = touchdown !== null && report.landing_error_m !== null;
    if (measured) nearPad.push({ t: touchdown, v: report.landing_error_m });
    const disagree = measured && lastGnss !== null && Math.abs(lastGnss - report.landing_error_m) > 0.5
      ? ` The GNSS track's last point was ${num(lastGnss, 1, "m")} from the base's surveyed position: that survey or the UAV's fix is off by about as much.`
      : "";
    clear(box,
      h("p", {}, `${name(run.uav_id)} from ${name(run.base_id)}, started ${when(run.created_at)}. `, stateBadge(run),
        " ", h("b", {}, outcomeWords(run) ? `${outcomeWords(run)}. ` : ""), run.reason),
      h("div", { class: "figures" },
        h("div", {}, h("b", {}, report.flight_time_s === null ? "–" : num(report.flight_time_s, 0, "s")), "Flight time"),
        h("div", {}, h("b", {}, num(report.battery_used_pct, 1, "%")), "Battery used"),
        h("div", {}, h("b", {}, report.landing_error_m === null ? "not measured" : num(report.landing_error_m * 100, 1, "cm")), "Landing error"),
        h("div", {}, h("b", {}, landing ? (landing.base_confirmed ? "yes" : "no") : "–"), "Base confirmed the landing"),
        h("div", {}, h("b", {}, track.length), "Track samples")),
      stepList(run),
      h("p", {}, h("a", { href: `#/replay/${run.id}` }, "Replay this run")),
      h("div", { class: "plots" },
        figure("Altitude above home (m)", lineChart({ title: "Altitude", unit: "m", points: series("position.alt_rel_m"), t0, t1, marks })),
        figure("Battery (%)", lineChart({ title: "Battery", unit: "%", points: series("battery.percent"), t0, t1, marks })),
        figure("Ground speed (m/s)", lineChart({ title: "Ground speed", unit: "m/s", points: f.speed, t0, t1, marks })),
        figure(`Horizontal distance from the pad while landing (m): GNSS from the base's surveyed position${measured ? `, ending on the touchdown the agent measured, ${num(report.landing_error_m * 100, 1, "cm")}.${disagree}` : ""}`,
          lineChart({ title: "Landing error", unit: "m", points: nearPad })),
        f.origin ? figure("Flight track, metres around the base (mission dashed)",
          trackMap({ title: "Flight track", track, mission: f.mission ? missionPoints(f.mission, f.origin) : [], geo: f.origin })) : null),
      timelineTable(run));
  })().catch((err) => clear(box, h("p", { role: "alert", class: "error" }, `The report could not be loaded: ${err.message}`)));
}
