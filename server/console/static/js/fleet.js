// The fleet: every UAV and base of the organisation with its live state from /ws/operator.

import { get } from "./api.js";
import { commandButton } from "./commands.js";
import { freshness, noteAvailability, on, state } from "./live.js";
import { airspace, missionPoints, originOf } from "./geo.js";
import { trackMap } from "./plot.js";
import { FINAL } from "./runs.js";
import { livePanel } from "./video.js";
import { ago, badge, clear, clock, h, metres, num } from "./ui.js";

const trails = new Map(); // uav id -> [{north, east}] seen since the console opened
const flying = new Map(); // uav id -> the mission of its unfinished run, in metres around its base
const plans = new Map(); // uav id -> that mission as the API gives it (its geoFence and rally points)
const zonesOf = new Map(); // uav id -> the airspace zones that apply to its base's flights

function linkRow(asset) {
  const f = freshness(asset.id);
  if (f.age === null) return badge("no data yet", "warn");
  return f.stale ? badge(`stale: last data ${ago(f.age)}`, "bad") : badge(`connected · ${ago(f.age)}`, "ok");
}

function kv(pairs) {
  return h("dl", { class: "kv" }, pairs.flatMap(([k, v]) => [h("dt", {}, k), h("dd", {}, v)]));
}

function uavValues(asset, v) {
  const fix = v["gnss.fix"];
  return kv([
    ["Link", linkRow(asset)],
    ["Mode", `${v.flight_mode ?? "–"}${v.armed ? " · armed" : v.armed === false ? " · disarmed" : ""}`],
    ["State", v.landed_state ?? "–"],
    ["Battery", `${num(v["battery.percent"], 0, "%")} · ${num(v["battery.voltage_v"], 1, "V")}`],
    ["GNSS fix", fix ? badge(`${fix} · ${v["gnss.satellites"] ?? "?"} sats`, fix === "none" ? "bad" : fix.startsWith("rtk") ? "ok" : "") : "–"],
    ["Position", v["position.lat"] !== undefined ? `${num(v["position.lat"], 6)}, ${num(v["position.lon"], 6)}` : "–"],
    ["Altitude", num(v["position.alt_rel_m"], 1, "m above home")],
    // the autopilot keeps its last mission's item after landing: shown only while it flies
    ["Mission item", v["mission.total"] && v.armed && v.landed_state !== "on_ground"
      ? `${v["mission.current"] + 1} of ${v["mission.total"]}` : v["mission.total"] ? "– (on the ground)" : "–"],
  ]);
}

function goNoGo(asset) {
  const a = state.availability.get(asset.id);
  if (!a) return h("span", { class: "muted" }, "not checked yet");
  const reason = a.available
    ? "all conditions met"
    : (a.failed || []).map((c) => c.message).join("; ") || a.reason;
  return h("span", {}, badge(a.available ? "GO" : "NO-GO", a.available ? "ok" : "bad"), " ", reason,
    h("span", { class: "muted" }, ` (checked ${ago(Date.now() - a.at)})`));
}

function baseValues(asset, v) {
  const motion = (p) => v[`${p}.state`] ? `${v[`${p}.state`]} · ${num(v[`${p}.position_pct`], 0, "%")}` : "–";
  const faults = v["faults.names"] && v["faults.names"].length ? v["faults.names"].join(", ") : "none";
  return kv([
    ["Link", linkRow(asset)],
    ["PLC link", v.plc_link ? badge(v.plc_link, v.plc_link === "up" ? "ok" : "bad") : "–"],
    ["Panels", motion("panels")],
    ["Lift", motion("lift")],
    ["UAV on pad", v.uav_present === undefined ? "–" : v.uav_present ? `yes · ${num(v.scale_mass_g, 0, "g")}${v.landing_confirmed ? " · landing confirmed" : ""}` : `no · ${num(v.scale_mass_g, 0, "g")}`],
    ["Charger", v["charger.state"] ? `${v["charger.state"]} · ${num(v["charger.current_a"], 1, "A")} · UAV battery ${num(v["charger.uav_battery_pct"], 0, "%")}` : "–"],
    ["Weather", v["weather.wind_m_s"] !== undefined ? `wind ${num(v["weather.wind_m_s"], 1, "m/s")}, gust ${num(v["weather.gust_m_s"], 1, "m/s")}, rain ${num(v["weather.rain_mm_h"], 1, "mm/h")}, ${num(v["weather.temperature_c"], 1, "°C")}` : "–"],
    ["Go / no-go", goNoGo(asset)],
    ["E-stop", v.estop ? badge("PRESSED", "bad") : v.estop === false ? "released" : "–"],
    ["Faults", faults],
  ]);
}

function card(ctx, asset) {
  const values = h("div");
  const out = h("p", { role: "status", "aria-live": "polite", class: "muted" });
  const mapBox = h("div");
  const title = asset.kind === "uav" ? "UAV" : "Landing base";
  // a UAV described as having no camera (attributes.camera false) gets no video panel
  const video = asset.kind === "uav" && (asset.attributes || {}).camera !== false ? livePanel(asset) : null;
  const actions = [];
  if (ctx.canOperate && asset.kind === "uav") {
    actions.push(commandButton(asset, "Return to base", "return_to_base", {
      out, danger: true,
      body: `${asset.name} will fly back to its base and land on the pad (precision landing).`,
    }));
  }
  if (ctx.canOperate && asset.kind === "landing_base") {
    actions.push(
      commandButton(asset, "Check availability", "check_availability", {
        out, body: `Ask ${asset.name} whether weather and base allow a flight now. Nothing moves.`,
        onFinal: (c) => noteAvailability(asset.id, c.status, c.reason, c.result, Date.now()),
      }),
      commandButton(asset, "Open base", "open", {
        out, body: `Open ${asset.name} for maintenance: panels open, then the lift goes up.`,
      }),
      commandButton(asset, "Close base", "close", {
        out, danger: true, body: `Close ${asset.name}: the lift goes down, then the panels close.`,
      }),
    );
  }
  const section = h("section", { class: "card", "aria-labelledby": `t-${asset.id}`, "data-asset": asset.id },
    h("h2", { id: `t-${asset.id}` }, `${title} ${asset.name}`),
    asset.description ? h("p", { class: "muted" }, asset.description) : null,
    values,
    actions.length ? h("div", { class: "actions", role: "group", "aria-label": `Commands for ${asset.name}` }, actions) : null,
    out,
    asset.kind === "uav" ? h("div", { class: "views" }, mapBox, video ? video.el : null) : null);
  // the map and the video are the card's costly parts: drawn and watched only while the card is
  // on (or near) the screen — off it the browser skips the card's rendering (app.css:
  // content-visibility) and says so
  let skipped = false;
  let mapStale = false;
  const drawMap = () => {
    mapStale = false;
    const v = (state.telemetry.get(asset.id) || { values: {} }).values;
    const origin = originOf(ctx, asset);
    const trail = trails.get(asset.id) || [];
    const here = origin && v["position.lat"] !== undefined ? metres(origin, v["position.lat"], v["position.lon"]) : null;
    clear(mapBox, origin
      ? h("figure", {}, h("figcaption", {}, flying.has(asset.id) ? "Live track and the current run's mission (dashed), metres around the base" : "Live track, metres around the base"),
        trackMap({ title: `Live track of ${asset.name}`, track: trail, uav: here, mission: flying.get(asset.id) || [], geo: origin,
          airspace: airspace(origin, zonesOf.get(asset.id) || [], plans.get(asset.id)) }))
      : h("p", { class: "muted" }, "No map: the base's position (attributes latitude, longitude) is unknown."));
  };
  section.addEventListener("contentvisibilityautostatechange", (e) => {
    skipped = e.skipped;
    if (video) video.shown(!skipped); // no video session for a card off the screen
    if (!skipped && mapStale) drawMap();
  });
  // values: the link's age and the latest sample; withMap: the track too (not for the clock)
  const update = (withMap = true) => {
    const t = state.telemetry.get(asset.id);
    const v = t ? t.values : {};
    section.classList.toggle("stale", freshness(asset.id).stale);
    clear(values, asset.kind === "uav" ? uavValues(asset, v) : baseValues(asset, v));
    if (asset.kind === "uav" && withMap) {
      if (skipped) mapStale = true;
      else drawMap();
    }
  };
  return { asset, section, update, stop: () => video && video.stop() };
}

function eventsTable(ctx) {
  const name = (id) => (ctx.byId.get(id) || { name: "?" }).name;
  const rows = state.events.slice(0, 15);
  if (!rows.length) return h("p", { class: "muted" }, "No events in the last hour.");
  const tone = { critical: "bad", warning: "warn", info: "" };
  return h("table", {},
    h("caption", {}, "Recent events (newest first)"),
    h("thead", {}, h("tr", {}, ["Time", "Asset", "Severity", "Event"].map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, rows.map((e) => h("tr", {},
      h("td", {}, clock(new Date(e.ts).toISOString())), h("td", {}, name(e.asset_id)),
      h("td", {}, badge(e.severity, tone[e.severity] || "")), h("td", {}, e.message || e.name)))));
}

let eventsLoaded = false; // the last hour's events are read once per sign-in; the socket adds the rest
on("stopped", () => { eventsLoaded = false; trails.clear(); });

export function render(main, ctx) {
  const uavs = ctx.assets.filter((a) => a.kind === "uav");
  const bases = ctx.assets.filter((a) => a.kind === "landing_base");
  const cards = new Map([...bases, ...uavs].map((a) => [a.id, card(ctx, a)]));
  const events = h("div", { "aria-live": "polite" });
  const showEvents = () => clear(events, eventsTable(ctx));
  showEvents();
  if (!eventsLoaded && ctx.assets.length) {
    eventsLoaded = true;
    const since = encodeURIComponent(new Date(Date.now() - 3600e3).toISOString());
    Promise.all(ctx.assets.map((a) => get(`/assets/${a.id}/events?start=${since}`).catch(() => []))).then((lists) => {
      const known = new Set(state.events.map((e) => `${e.asset_id}|${e.name}|${e.ts}`));
      const stored = lists.flat().map((e) => ({ ...e, ts: Date.parse(e.ts) }))
        .filter((e) => !known.has(`${e.asset_id}|${e.name}|${e.ts}`));
      state.events = [...state.events, ...stored].sort((x, y) => y.ts - x.ts).slice(0, 50);
      showEvents();
    });
  }
  clear(main,
    h("h1", {}, "Fleet"),
    ctx.assets.length ? null : h("p", {}, "This organisation has no assets yet."),
    h("div", { class: "fleet" },
      bases.length ? h("div", {}, h("h2", {}, "Landing bases"), h("div", { class: "stack-cards" }, bases.map((a) => cards.get(a.id).section))) : null,
      uavs.length ? h("div", {}, h("h2", {}, "UAVs"), h("div", { class: "stack-cards" }, uavs.map((a) => cards.get(a.id).section))) : null),
    ctx.assets.length ? h("section", { "aria-labelledby": "events-title" }, h("h2", { id: "events-title" }, "Events"), events) : null,
  );
  for (const c of cards.values()) c.update();
  // what the socket has not brought yet: the newest stored sample and the last availability check
  for (const a of ctx.assets) {
    if (!state.telemetry.has(a.id)) {
      get(`/assets/${a.id}/telemetry/latest`).then((row) => {
        if (state.telemetry.has(a.id)) return;
        state.telemetry.set(a.id, { values: row, at: Date.parse(row.ts) });
        cards.get(a.id).update();
      }).catch(() => {});
    }
    if (a.kind === "landing_base" && !state.availability.has(a.id)) {
      get(`/assets/${a.id}/commands?limit=50`).then((list) => {
        const c = list.find((x) => x.name === "check_availability" && x.result && "available" in x.result);
        if (c && !state.availability.has(a.id)) noteAvailability(a.id, c.status, c.reason, c.result, Date.parse(c.updated_at));
      }).catch(() => {});
    }
  }
  // the mission of each UAV's unfinished run, drawn under its live track
  const missions = async () => {
    for (const u of uavs) {
      const [run] = await get(`/runs?uav_id=${u.id}&limit=1`).catch(() => []);
      const origin = originOf(ctx, u);
      if (run && !FINAL.has(run.state) && origin) {
        const m = await get(`/missions/${run.mission_id}`).catch(() => null);
        if (m) { flying.set(u.id, missionPoints(m, origin)); plans.set(u.id, m); }
      } else { flying.delete(u.id); plans.delete(u.id); }
      cards.get(u.id).update();
    }
  };
  missions();
  // the zones over each UAV's map: those that apply to flights from its base
  for (const u of uavs) {
    const b = u.base_id || (bases[0] || {}).id;
    get(`/airspace/zones?limit=1000${b ? `&base_id=${b}` : ""}`)
      .then((zones) => { zonesOf.set(u.id, zones); cards.get(u.id).update(); }).catch(() => {});
  }
  let pending = new Set();
  let frame = null;
  const offs = [
    on("telemetry", (p) => {
      const c = cards.get(p.asset_id);
      if (!c) return;
      if (c.asset.kind === "uav" && p.position) {
        const origin = originOf(ctx, c.asset);
        if (origin) {
          const trail = trails.get(p.asset_id) || [];
          trail.push(metres(origin, p.position.lat, p.position.lon));
          if (trail.length > 1500) trail.splice(0, trail.length - 1500);
          trails.set(p.asset_id, trail);
        }
      }
      pending.add(c);
      frame = frame || requestAnimationFrame(() => { frame = null; for (const x of pending) x.update(); pending = new Set(); });
    }),
    on("availability", (id) => cards.get(id) && cards.get(id).update()),
    on("event", showEvents),
    on("run_progress", (p) => { if (p.state === "checking" || p.final) missions(); }),
    on("tick", () => { for (const c of cards.values()) c.update(false); }),
  ];
  return () => {
    offs.forEach((f) => f());
    if (frame) cancelAnimationFrame(frame);
    for (const c of cards.values()) c.stop(); // each live video session ends (WHEP DELETE)
  };
}
