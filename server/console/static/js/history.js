// History: the fleet summary and past runs with outcome and cause.

import { get } from "./api.js";
import { FINAL, OUTCOMES, causeWords, outcomeWords, stateBadge } from "./runs.js";
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
        ...[["Runs", fleet.runs], ["Completed", fleet.completed], ["Completed with issues", fleet.completed_with_issues],
          ["Incomplete", fleet.incomplete], ["Aborted", fleet.aborted], ["Failed", fleet.failed],
          ["In progress", fleet.in_progress],
          ["Success rate", fleet.success_rate === null || fleet.success_rate === undefined ? "–" : `${Math.round(fleet.success_rate * 100)} %`],
          ["Mean flight", fleet.mean_flight_time_s ? num(fleet.mean_flight_time_s / 60, 1, "min") : "–"]]
          .map(([k, v]) => h("div", {}, h("b", {}, v), k))),
      h("p", { class: "muted" }, "Success rate: completed runs over finished runs; a run completed with issues or incomplete is not a success."),
      Object.keys(fleet.by_outcome || {}).length
        ? h("ul", { "aria-label": "Runs not completed, by outcome and cause" },
          Object.entries(fleet.by_outcome).map(([o, causes]) => h("li", {}, h("b", {}, `${(OUTCOMES[o] || [o])[0]}: `),
            Object.entries(causes).map(([c, n]) => `${causeWords(c)} ${n}`).join(", "))))
        : null));
    const past = runs.filter((r) => FINAL.has(r.state));
    clear(table, past.length ? h("table", {},
      h("caption", {}, "Past runs (newest first)"),
      h("thead", {}, h("tr", {}, ["Started", "UAV", "Outcome", "In words, and the reason", "Report", "Replay"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, past.map((r) => h("tr", {},
        h("td", {}, when(r.created_at)), h("td", {}, name(r.uav_id)), h("td", {}, stateBadge(r)),
        h("td", {}, h("b", {}, `${outcomeWords(r)}. `), r.reason),
        h("td", {}, h("a", { href: `#/report/${r.id}`, "aria-label": `Report of the run started ${when(r.created_at)}` }, "Report")),
        h("td", {}, h("a", { href: `#/replay/${r.id}`, "aria-label": `Replay of the run started ${when(r.created_at)}` }, "Replay"))))))
      : h("p", {}, "No finished runs yet."));
  })().catch((err) => clear(table, h("p", { role: "alert", class: "error" }, `Could not be loaded: ${err.message}`)));
}
