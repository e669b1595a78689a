// Runs: the live timeline of each run with its eight steps, Abort, and starting or scheduling one.

import { api, get, post } from "./api.js";
import { on } from "./live.js";
import { badge, clear, clock, confirmDialog, h, notify, when } from "./ui.js";

export const STEPS = [
  ["checking", "Checking availability"],
  ["opening", "Opening the base"],
  ["uploading", "Uploading the mission"],
  ["flying", "Flying the mission"],
  ["landing", "Returning and landing"],
  ["confirming", "Confirming the landing"],
  ["closing", "Closing the base"],
  ["charging", "Starting to charge"],
];
export const FINAL = new Set(["completed", "incomplete", "aborted", "failed"]);

// a finished run's outcome in words, the same in the runs page, the history and the report
// (server/runs/outcome.py, frontend_api.md "Outcomes"): only "completed" is the job done cleanly
export const OUTCOMES = {
  completed: ["completed", "ok"],
  completed_with_issues: ["completed with issues", "warn"],
  incomplete: ["incomplete", "warn"],
  aborted: ["aborted", "bad"],
  failed: ["failed", "bad"],
};
export const CAUSES = {
  battery_reserve: "returned early: battery reserve",
  fence_breach: "returned early: geofence breach",
  mission_overrun: "returned early: mission overran its time",
  operator_return: "returned early: an operator sent it home",
  returned_early: "returned early on its own",
  charging_refused: "charging refused",
  landing_off_contacts: "landed off the charging contacts",
  landed_without_precision: "landed on GNSS alone (precision landing sent nothing)",
  operator_abort: "aborted by an operator",
  home_out_of_reach: "home out of reach: landed where it was",
};

export function causeWords(cause) {
  return cause ? CAUSES[cause] || cause.replaceAll("_", " ") : "";
}

export function stateBadge(run) {
  if (FINAL.has(run.state) && OUTCOMES[run.outcome]) {
    const [words, tone] = OUTCOMES[run.outcome];
    return badge(words, tone);
  }
  return badge(run.state, FINAL.has(run.state) ? "bad" : "warn");
}

// "incomplete: returned early: battery reserve", "completed with issues: charging refused"
export function outcomeWords(run) {
  if (!FINAL.has(run.state)) return "";
  const [words] = OUTCOMES[run.outcome] || [run.state];
  const issues = (run.issues || []).map(causeWords);
  const why = run.outcome === "completed_with_issues" ? issues : [causeWords(run.cause), ...issues];
  const said = [...new Set(why.filter(Boolean))];
  return said.length ? `${words}: ${said.join("; ")}` : words;
}

// the step where a run that did not complete stopped (or turned home), from its timeline
function stoppedAt(run) {
  const tl = run.timeline || [];
  if (run.state === "incomplete") {
    const turned = tl.find((t) => t.from_state === "flying" && t.to_state !== "flying");
    return turned ? "flying" : null;
  }
  if (run.state !== "failed" && run.state !== "aborted") return null;
  // the first entry of its cause: an abort asked while landing is noted in the landing step
  const first = run.cause ? tl.find((t) => t.cause === run.cause) : null;
  const last = [...tl].reverse().find((t) => t.to_state === run.state);
  return (first || last || {}).from_state || null;
}

// the eight steps with the current one marked (aria-current="step")
export function stepList(run) {
  const reached = new Set((run.timeline || []).map((t) => t.to_state));
  const names = STEPS.map(([n]) => n);
  const stopped = stoppedAt(run); // the step a run that did not complete stopped in
  const issues = (run.issues || []).map(causeWords).join("; ");
  return h("ol", { class: "steps", "aria-label": "Steps of the run" }, STEPS.map(([name, label], i) => {
    const current = !FINAL.has(run.state) && run.state === name;
    const failed = stopped === name;
    const done = !current && !failed && (reached.has(name) && (run.state === "completed" || names.indexOf(run.state) > i || FINAL.has(run.state)));
    const issue = done && name === "charging" && issues ? ` ⚠ ${issues}` : "";
    const here = run.state === "incomplete" ? " (turned home here)" : ` (${run.state} here)`;
    return h("li", {
      class: failed ? "failed" : issue ? "failed" : done ? "done" : "",
      "aria-current": current ? "step" : null,
    }, `${i + 1}. ${label}`, current ? " (now)" : failed ? here : issue || (done ? " ✓" : ""));
  }));
}

export function timelineTable(run) {
  return h("table", { class: "timeline" },
    h("caption", {}, "Timeline"),
    h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "Time"), h("th", { scope: "col" }, "Step"), h("th", { scope: "col" }, "Reason"))),
    h("tbody", {}, (run.timeline || []).map((t) => h("tr", {},
      h("td", {}, clock(t.at)),
      h("td", {}, t.from_state === t.to_state ? t.to_state : `${t.from_state} → ${t.to_state}`),
      h("td", {}, t.reason, t.cause ? h("span", { class: "muted" }, ` (${t.cause})`) : null)))));
}

function runDetail(ctx, run, refresh) {
  const name = (id) => (ctx.byId.get(id) || { name: id.slice(0, 8) }).name;
  const abort = ctx.canOperate && !FINAL.has(run.state)
    ? h("button", {
      type: "button", class: "danger", disabled: run.abort_requested,
      onclick: async () => {
        const v = await confirmDialog({
          title: "Abort the run",
          body: `Abort the run of ${name(run.uav_id)}? Before take-off the base closes; in flight the UAV returns to the base, lands and the base closes over it.`,
          confirm: "Abort the run", danger: true,
          inputs: [{ name: "reason", label: "Reason (written in the timeline)", value: "aborted from the console" }],
        });
        if (!v) return;
        try {
          await post(`/runs/${run.id}/abort`, { reason: v.reason });
          notify("Abort requested: the run goes to its safe outcome.");
        } catch (err) { notify(`Abort refused: ${err.message}`, "bad"); }
        refresh();
      },
    }, run.abort_requested ? "Abort requested" : "Abort run")
    : null;
  return h("section", { class: "card", "aria-labelledby": "run-title" },
    h("h2", { id: "run-title" }, `Run of ${name(run.uav_id)} from ${name(run.base_id)}`),
    h("p", {}, stateBadge(run), " ", FINAL.has(run.state) ? outcomeWords(run) : run.label || "", run.alert ? badge("ALERT: a person should look", "bad") : null),
    run.reason ? h("p", { class: "reason" }, FINAL.has(run.state) ? "" : "Last step: ", run.reason) : null,
    stepList(run),
    abort ? h("div", { class: "actions" }, abort) : null,
    timelineTable(run),
    h("p", {}, FINAL.has(run.state) ? h("a", { href: `#/report/${run.id}` }, "Open the run report") : null));
}

function startForm(ctx, missions, done) {
  const uavs = ctx.assets.filter((a) => a.kind === "uav");
  const tz = Intl.DateTimeFormat().resolvedOptions().timeZone || "UTC";
  const error = h("div", { role: "alert", class: "error" });
  const field = (id, label, input) => h("div", { class: "field" }, h("label", { for: id }, label), input);
  const mission = h("select", { id: "run-mission", required: true }, missions.map((m) => h("option", { value: m.id }, m.name)));
  const uav = h("select", { id: "run-uav", required: true }, uavs.map((u) => h("option", { value: u.id }, u.name)));
  const base = h("output", { id: "run-base" });
  const kind = h("select", { id: "run-when" },
    h("option", { value: "now" }, "Now"), h("option", { value: "once" }, "Once, at a time"),
    h("option", { value: "interval" }, "Every N minutes"), h("option", { value: "cron" }, "Cron expression"));
  const name = h("input", { id: "run-name", type: "text", value: "console schedule" });
  const at = h("input", { id: "run-at", type: "datetime-local", step: 1 });
  const every = h("input", { id: "run-every", type: "number", min: 1, value: 60 });
  const cron = h("input", { id: "run-cron", type: "text", value: "0 6 * * *" });
  const zone = h("input", { id: "run-tz", type: "text", value: tz });
  const parts = {
    name: field("run-name", "Schedule name", name),
    at: field("run-at", "At (your local time)", at),
    every: field("run-every", "Every (minutes, at least 1)", every),
    cron: field("run-cron", "Cron (minute hour day month weekday)", cron),
    zone: field("run-tz", "Time zone (IANA)", zone),
  };
  const showFields = () => {
    const k = kind.value;
    parts.name.hidden = k === "now";
    parts.at.hidden = k !== "once" && k !== "interval";
    parts.every.hidden = k !== "interval";
    parts.cron.hidden = k !== "cron";
    parts.zone.hidden = k !== "cron";
    const b = ctx.byId.get((ctx.byId.get(uav.value) || {}).base_id);
    base.textContent = b ? b.name : "this UAV has no base";
  };
  kind.addEventListener("change", showFields);
  uav.addEventListener("change", showFields);
  const submit = async (e) => {
    e.preventDefault();
    error.textContent = "";
    const u = ctx.byId.get(uav.value);
    const ids = { mission_id: mission.value, uav_id: uav.value, base_id: u && u.base_id };
    try {
      if (kind.value === "now") {
        const run = await post("/runs", ids);
        notify("Run started.");
        return done(run.id);
      }
      const body = { name: name.value, ...ids, kind: kind.value };
      if (kind.value === "once" || (kind.value === "interval" && at.value)) {
        if (!at.value) throw new Error("choose the time of the run");
        body.at = new Date(at.value).toISOString();
      }
      if (kind.value === "interval") body.interval_s = Math.round(Number(every.value) * 60);
      if (kind.value === "cron") { body.cron = cron.value; body.timezone = zone.value; }
      const s = await post("/schedules", body);
      notify(`Scheduled: next run ${when(s.next_due_at)}.`);
      done(null);
    } catch (err) {
      const details = Array.isArray(err.details) ? err.details.map((d) => d.msg || d.what).filter(Boolean) : [];
      clear(error, err.message, details.length > 1 ? h("ul", {}, details.map((d) => h("li", {}, d))) : null);
    }
  };
  const form = h("form", { class: "stack", "aria-labelledby": "start-title", onsubmit: submit },
    h("h2", { id: "start-title" }, "Start or schedule a run"),
    missions.length ? null : h("p", {}, "Import or create a mission first."),
    field("run-mission", "Mission", mission),
    field("run-uav", "UAV", uav),
    h("div", { class: "field" }, h("span", {}, "Base"), base),
    field("run-when", "When", kind),
    ...Object.values(parts),
    h("button", { type: "submit", class: "primary", disabled: !missions.length || !uavs.length }, "Start or schedule"),
    error);
  showFields();
  return form;
}

function schedulesTable(ctx, schedules, refresh) {
  if (!schedules.length) return h("p", { class: "muted" }, "No schedules.");
  return h("table", {},
    h("caption", {}, "Schedules"),
    h("thead", {}, h("tr", {}, ["Name", "Timing", "Next", "Last result", ctx.canOperate ? "Actions" : null].filter(Boolean).map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, schedules.map((s) => h("tr", {},
      h("td", {}, s.name, s.enabled ? "" : h("span", { class: "muted" }, " (disabled)")),
      h("td", {}, s.kind === "cron" ? `cron ${s.cron} (${s.timezone})` : s.kind === "interval" ? `every ${Math.round(s.interval_s / 60)} min` : `once at ${when(s.at)}`),
      h("td", {}, s.enabled ? when(s.next_due_at) : "–"),
      h("td", {}, s.last_result || "–"),
      ctx.canOperate ? h("td", {},
        h("button", { type: "button", "aria-label": `${s.enabled ? "Disable" : "Enable"} schedule ${s.name}`,
          onclick: async () => { await api("PATCH", `/schedules/${s.id}`, { enabled: !s.enabled }); refresh(); } }, s.enabled ? "Disable" : "Enable"), " ",
        h("button", { type: "button", "aria-label": `Delete schedule ${s.name}`,
          onclick: async () => {
            if (await confirmDialog({ title: "Delete the schedule", body: `Delete ${s.name}? Its past runs stay.`, confirm: "Delete", danger: true })) {
              await api("DELETE", `/schedules/${s.id}`); refresh();
            }
          } }, "Delete")) : null))));
}

export function runsTable(ctx, runs, selected, caption) {
  const name = (id) => (ctx.byId.get(id) || { name: "?" }).name;
  return h("table", {},
    h("caption", {}, caption),
    h("thead", {}, h("tr", {}, ["Started", "UAV", "State or outcome", "Step or cause", ""].map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, runs.map((r) => h("tr", { class: r.id === selected ? "selected" : "" },
      h("td", {}, when(r.created_at)),
      h("td", {}, name(r.uav_id)),
      h("td", {}, stateBadge(r), r.schedule_id ? h("span", { class: "muted" }, " scheduled") : null),
      h("td", {}, FINAL.has(r.state) ? outcomeWords(r) : `${r.step}/${r.total_steps} ${r.label}`),
      h("td", {}, h("a", { href: `#/runs/${r.id}`, "aria-label": `Open run of ${name(r.uav_id)} started ${when(r.created_at)}` }, "Open"))))));
}

export function render(main, ctx, args) {
  let selected = args[0] || null;
  const formBox = h("div");
  const list = h("div");
  const left = h("div", {}, formBox, list);
  const right = h("div", { "aria-live": "polite" });
  clear(main, h("h1", {}, "Runs"), h("div", { class: "cols" }, left, right));
  let missions = [];
  let timer = null;

  async function draw() {
    const [runs, schedules] = await Promise.all([get("/runs?limit=30"), get("/schedules?limit=100")]);
    if (!selected && runs.length) selected = (runs.find((r) => !FINAL.has(r.state)) || runs[0]).id;
    clear(list,
      runs.length ? runsTable(ctx, runs, selected, "Recent runs (newest first)") : h("p", {}, "No runs yet."),
      schedulesTable(ctx, schedules, refresh));
    if (selected) {
      try {
        clear(right, runDetail(ctx, await get(`/runs/${selected}`), refresh));
      } catch (err) {
        if (err.status !== 404) throw err;
        clear(right, h("p", { role: "alert" }, "No such run in your organisation."));
      }
    } else clear(right, h("p", { class: "muted" }, "Start a run to see its timeline here."));
  }
  // one draw at a time: asked again meanwhile, it draws once more when done. Overlapping draws on
  // a slow server finished in any order, and an older answer (the run two steps ago) replaced a
  // newer one
  let drawing = null;
  let again = false;
  function refresh() {
    if (drawing) { again = true; return drawing; }
    drawing = (async () => {
      do { again = false; await draw(); } while (again);
    })().finally(() => { drawing = null; });
    return drawing;
  }
  const soon = () => { clearTimeout(timer); timer = setTimeout(() => refresh().catch(() => {}), 150); };

  (async () => {
    if (ctx.canOperate) {
      missions = await get("/missions?limit=1000");
      clear(formBox, h("section", { class: "card" }, startForm(ctx, missions, (id) => {
        if (id) { location.hash = `#/runs/${id}`; } else soon();
      })));
    }
    await refresh();
  })().catch((err) => clear(right, h("p", { role: "alert", class: "error" }, `Runs could not be loaded: ${err.message}`)));
  const offs = [on("run_progress", soon), on("reconnected", soon)];
  // schedules fire on the server: a slow poll notices a new run before its first progress message
  const poll = setInterval(soon, 10000);
  return () => { offs.forEach((f) => f()); clearInterval(poll); clearTimeout(timer); };
}
