// History: the fleet summary and past runs with outcome and cause.

import { get } from "./api.js";
import { FINAL, stateBadge } from "./runs.js";
import { clear, h, num, when } from "./ui.js";

export function render(main, ctx) {
  const summary = h("div");
  const table = h("div");
  clear(main, h("h1", {}, "History"), summary, table);
  const name = (id) => (ctx.byId.get(id) || { name: "?" }).name;
  (async () => {
    const [fleet, runs] = await Promise.all([get("/reports/fleet"), get("/runs?limit=200")]);
    clear(summary, h("section", { class: "card", "aria-labelledby": "fleet-title" },
      h("h2", { id: "fleet-title" }, `Fleet summary, ${when(fleet.start)} to ${when(fleet.end)}`),
      h("div", { class: "figures" },
        ...[["Runs", fleet.runs], ["Completed", fleet.completed], ["Aborted", fleet.aborted], ["Failed", fleet.failed],
          ["In progress", fleet.in_progress],
          ["Success rate", fleet.success_rate === null || fleet.success_rate === undefined ? "–" : `${Math.round(fleet.success_rate * 100)} %`],
          ["Mean flight", fleet.mean_flight_time_s ? num(fleet.mean_flight_time_s / 60, 1, "min") : "–"]]
          .map(([k, v]) => h("div", {}, h("b", {}, v), k))),
      Object.keys(fleet.failures_by_cause || {}).length
        ? h("p", {}, "Failures by cause: ", Object.entries(fleet.failures_by_cause).map(([c, n]) => `${c} ${n}`).join(", "))
        : null));
    const past = runs.filter((r) => FINAL.has(r.state));
    clear(table, past.length ? h("table", {},
      h("caption", {}, "Past runs (newest first)"),
      h("thead", {}, h("tr", {}, ["Started", "UAV", "Outcome", "Cause and reason", "Report", "Replay"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, past.map((r) => h("tr", {},
        h("td", {}, when(r.created_at)), h("td", {}, name(r.uav_id)), h("td", {}, stateBadge(r)),
        h("td", {}, r.cause ? h("b", {}, `${r.cause}: `) : null, r.reason),
        h("td", {}, h("a", { href: `#/report/${r.id}`, "aria-label": `Report of the run started ${when(r.created_at)}` }, "Report")),
        h("td", {}, h("a", { href: `#/replay/${r.id}`, "aria-label": `Replay of the run started ${when(r.created_at)}` }, "Replay"))))))
      : h("p", {}, "No finished runs yet."));
  })().catch((err) => clear(table, h("p", { role: "alert", class: "error" }, `Could not be loaded: ${err.message}`)));
}
