// Missions: the list, importing a QGroundControl .plan (or waypoint file) with every refused item
// named, a mission's items on the local map, and export.

import { api, ApiError, get, post } from "./api.js";
import { airspace, distanceM, distanceText, flownTo, missionPoints, positionOf } from "./geo.js";
import { trackMap } from "./plot.js";
import { clear, h, metres, notify, num, when } from "./ui.js";

const NAMES = {
  16: "WAYPOINT", 17: "LOITER_UNLIM", 18: "LOITER_TURNS", 19: "LOITER_TIME", 20: "RETURN_TO_LAUNCH",
  21: "LAND", 22: "TAKEOFF", 82: "SPLINE_WAYPOINT", 93: "DELAY", 112: "CONDITION_DELAY", 115: "CONDITION_YAW",
  177: "DO_JUMP", 178: "DO_CHANGE_SPEED", 181: "DO_SET_RELAY", 183: "DO_SET_SERVO", 195: "DO_SET_ROI_LOCATION",
  197: "DO_SET_ROI_NONE", 201: "DO_SET_ROI", 203: "DO_DIGICAM_CONTROL", 205: "DO_MOUNT_CONTROL",
  206: "DO_SET_CAM_TRIGG_DIST", 530: "SET_CAMERA_MODE", 2000: "IMAGE_START_CAPTURE", 2001: "IMAGE_STOP_CAPTURE",
  2500: "VIDEO_START_CAPTURE", 2501: "VIDEO_STOP_CAPTURE", 30: "CONTINUE_AND_CHANGE_ALT", 84: "NAV_VTOL_TAKEOFF", 85: "NAV_VTOL_LAND",
};
async function download(mission, format) {
  const r = await api("GET", `/missions/${mission.id}/export?format=${format}`, undefined, { raw: true });
  const blob = await r.blob();
  const disposition = r.headers.get("Content-Disposition") || "";
  const m = /filename="([^"]+)"/.exec(disposition);
  const a = h("a", { href: URL.createObjectURL(blob), download: m ? m[1] : `${mission.name}.${format === "wpl" ? "waypoints" : "plan"}` });
  document.body.append(a);
  a.click();
  setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 1000);
}

function problemsTable(err) {
  const rows = Array.isArray(err.details) ? err.details : [];
  return h("div", { role: "alert" },
    h("p", { class: "error" }, `Import refused (${err.code}): ${err.message}`),
    rows.length ? h("table", {},
      h("caption", {}, `${rows.length} problem${rows.length > 1 ? "s" : ""}, by item`),
      h("thead", {}, h("tr", {}, ["Item", "Command", "Where", "Problem", "Value", "Limit"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, rows.map((d) => h("tr", {},
        h("td", {}, d.index ?? "–"),
        h("td", {}, d.command !== undefined && d.command !== null ? `${d.command} ${NAMES[d.command] || ""}` : "–"),
        h("td", {}, d.where || (d.loc || []).join(".")),
        h("td", {}, d.what || d.msg || ""),
        h("td", {}, d.value === undefined ? "" : JSON.stringify(d.value)),
        h("td", {}, d.limit === undefined || d.limit === null ? "" : Array.isArray(d.limit) ? `${d.limit.slice(0, 6).join(", ")}…` : JSON.stringify(d.limit))))))
      : null);
}

function importForm(done) {
  const file = h("input", { id: "plan-file", type: "file", accept: ".plan,.json,.waypoints,.txt", required: true });
  const name = h("input", { id: "plan-name", type: "text", placeholder: "the file's name" });
  const out = h("div");
  const submit = async (e) => {
    e.preventDefault();
    clear(out);
    const f = file.files[0];
    if (!f) return;
    const json = /\.(plan|json)$/i.test(f.name);
    const title = name.value || f.name.replace(/\.[^.]+$/, "");
    try {
      const m = await api("POST", `/missions/import?name=${encodeURIComponent(title)}`, await f.text(),
        { contentType: json ? "application/json" : "text/plain" });
      notify(`Imported ${m.name}: ${m.items.length} items.`);
      file.value = "";
      done(m.id);
    } catch (err) {
      if (!(err instanceof ApiError)) throw err;
      clear(out, problemsTable(err));
    }
  };
  return h("form", { class: "stack card", "aria-labelledby": "import-title", onsubmit: submit },
    h("h2", { id: "import-title" }, "Import a mission"),
    h("label", { for: "plan-file" }, "QGroundControl .plan or waypoint file"), file,
    h("label", { for: "plan-name" }, "Name (optional)"), name,
    h("button", { type: "submit", class: "primary" }, "Import"),
    out);
}

// the mission checked against limits, the airspace and the reach, flown from the organisation's (first)
// base by a UAV that lives there: each problem with the segment, the zone and the distance the server names
function validation(m, base, uav) {
  const out = h("div", { "aria-live": "polite" }, h("p", { class: "muted" }, "Checking against the limits and the airspace…"));
  const from = `${base ? ` from ${base.name}` : ""}${uav ? ` with ${uav.name}` : ""}`;
  const body = { ...(base ? { base_id: base.id } : {}), ...(uav ? { uav_id: uav.id } : {}) };
  const metresOf = (d) => d.code === "airspace" || d.code === "out_of_reach";
  post(`/missions/${m.id}/validate`, body).then((r) => {
    const rows = r.problems || [];
    clear(out, rows.length ? h("table", {},
      h("caption", {}, `Not valid${from} now: ${rows.length} problem${rows.length > 1 ? "s" : ""}`),
      h("thead", {}, h("tr", {}, ["Kind", "Segment", "Zone", "Problem", "Distance / value", "Limit"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, rows.map((d) => h("tr", {},
        h("td", {}, d.code || d.where),
        h("td", {}, d.segment ? d.segment.join(" → ") : d.index ?? "–"),
        h("td", {}, d.zone ? `${d.zone.kind} ${d.zone.source === "plan" ? "fence" : "zone"} '${d.zone.name}'` : "–"),
        h("td", {}, d.what),
        h("td", {}, d.value === undefined || d.value === null ? "" : metresOf(d) ? `${num(d.value, 1, "m")}` : JSON.stringify(d.value)),
        h("td", {}, d.limit === undefined || d.limit === null ? "" : d.code === "out_of_reach" ? num(d.limit, 1, "m") : JSON.stringify(d.limit))))))
      : h("p", {}, `Valid${from} now: within the limits, the reach and clear of the airspace zones.`));
  }).catch((err) => clear(out, h("p", { role: "alert", class: "error" }, `Could not be checked: ${err.message}`)));
  return out;
}

const FAR_M = 5000; // beyond this an item is far from the base: the map says so, with the distance

// the map: the base at the centre with the mission around it and the legs to it and back; a base of
// unknown position leaves the mission's home (or its first item) at the centre, and the map says which
function missionMap(m, base, zones) {
  const at = positionOf(base);
  const first = m.items.find((it) => it.lat || it.lon);
  const origin = at || (m.home ? { lat: m.home.lat, lon: m.home.lon } : first ? { lat: first.lat, lon: first.lon } : null);
  if (!origin) return null;
  const flown = flownTo(m);
  const far = at && flown.length ? Math.max(...flown.map((it) => distanceM(at, it))) : 0;
  const near = at && flown.length ? distanceM(at, flown[0]) : 0;
  const notice = far > FAR_M
    ? h("p", { role: "status", class: "far-notice", "data-distance-m": Math.round(near) },
      `Far from the base: the mission's first item is ${distanceText(near)} from base ${base.name}` +
      `${far - near > 1 ? ` (its farthest ${distanceText(far)})` : ""}; both are drawn on one map at that scale.`)
    : null;
  // from the base the take-off climbs there: the map draws the items flown to, and the legs
  const points = at ? flown.map((it) => metres(origin, it.lat, it.lon)) : missionPoints(m, origin);
  const caption = at
    ? `The mission in metres around base ${base.name}, with the flights there and back, the zones and the plan's fence`
    : `The mission in metres around ${m.home ? "its home" : "its first item"} (${base ? `base ${base.name}'s position is unknown` : "no base"}), with the zones and the plan's fence`;
  return h("figure", {},
    h("figcaption", {}, caption), notice,
    trackMap({ title: `Mission ${m.name}`, mission: points, geo: origin, airspace: airspace(origin, zones, m),
      centre: at ? "base" : "home", legs: Boolean(at) }));
}

function detail(ctx, m) {
  const base = ctx.assets.find((a) => a.kind === "landing_base");
  const uav = base ? ctx.assets.find((a) => a.kind === "uav" && a.base_id === base.id) : null;
  const map = h("div");
  const draw = (zones) => clear(map, missionMap(m, base, zones));
  draw([]);
  get(`/airspace/zones?limit=1000${base ? `&base_id=${base.id}` : ""}`).then(draw).catch(() => {});
  return h("section", { class: "card", "aria-labelledby": "mission-title" },
    h("h2", { id: "mission-title" }, m.name),
    h("p", {}, `${m.kind}, from ${m.source}; ${m.items.length} items; about ${num(m.estimate.distance_m, 0, "m")}, ` +
      `${m.estimate.endless ? "endless" : num(m.estimate.flight_time_s / 60, 1, "min")}${m.estimate.note ? ` (${m.estimate.note})` : ""}`),
    h("div", { class: "actions" },
      h("button", { type: "button", "aria-label": `Export ${m.name} as a QGroundControl plan`, onclick: () => download(m, "qgc") }, "Export .plan"),
      h("button", { type: "button", "aria-label": `Export ${m.name} as a waypoint file`, onclick: () => download(m, "wpl") }, "Export waypoints")),
    map,
    ctx.canOperate ? validation(m, base, uav) : null,
    h("table", {},
      h("caption", {}, "Items"),
      h("thead", {}, h("tr", {}, ["#", "Command", "Frame", "Latitude", "Longitude", "Altitude"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, m.items.map((it, i) => h("tr", {},
        h("td", {}, i), h("td", {}, `${it.command} ${NAMES[it.command] || ""}`), h("td", {}, it.frame),
        h("td", {}, num(it.lat, 6)), h("td", {}, num(it.lon, 6)), h("td", {}, num(it.alt, 1)))))));
}

export function render(main, ctx, args) {
  const list = h("div");
  const right = h("div");
  clear(main, h("h1", {}, "Missions"),
    h("div", { class: "cols" }, h("div", {}, ctx.canOperate ? importForm((id) => { location.hash = `#/missions/${id}`; }) : null, list), right));
  (async () => {
    const missions = await get("/missions?limit=1000");
    clear(list, missions.length ? h("table", {},
      h("caption", {}, "Missions"),
      h("thead", {}, h("tr", {}, ["Name", "Kind", "Items", "Created", ""].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, missions.map((m) => h("tr", { class: m.id === args[0] ? "selected" : "" },
        h("td", {}, m.name), h("td", {}, `${m.kind} (${m.source})`), h("td", {}, m.items.length), h("td", {}, when(m.created_at)),
        h("td", {}, h("a", { href: `#/missions/${m.id}`, "aria-label": `Open mission ${m.name}` }, "Open"))))))
      : h("p", {}, "No missions yet."));
    const chosen = missions.find((m) => m.id === args[0]);
    if (chosen) clear(right, detail(ctx, chosen));
  })().catch((err) => clear(list, h("p", { role: "alert", class: "error" }, `Could not be loaded: ${err.message}`)));
}
