// Where things are: the base that is the map's origin, and a mission's points in metres around it.

import { metres } from "./ui.js";

export function originOf(ctx, uav) {
  const base = uav && uav.base_id ? ctx.byId.get(uav.base_id) : ctx.assets.find((a) => a.kind === "landing_base");
  return positionOf(base);
}

export function positionOf(base) {
  const a = base ? base.attributes || {} : {};
  return Number.isFinite(a.latitude) && Number.isFinite(a.longitude) ? { lat: a.latitude, lon: a.longitude } : null;
}

// great-circle metres between two {lat, lon} (the server's haversine, missions/geometry.py)
export function distanceM(a, b) {
  const r = 6371008.8, rad = Math.PI / 180;
  const dp = (b.lat - a.lat) * rad, dl = (b.lon - a.lon) * rad;
  const h = Math.sin(dp / 2) ** 2 + Math.cos(a.lat * rad) * Math.cos(b.lat * rad) * Math.sin(dl / 2) ** 2;
  return 2 * r * Math.asin(Math.min(1, Math.sqrt(h)));
}

// "1,712.4 km" from a kilometre up, else "850.0 m" (the server's wording, missions/reach.py)
export function distanceText(m) {
  const f = (v) => v.toLocaleString("en-GB", { minimumFractionDigits: 1, maximumFractionDigits: 1 });
  return m >= 1000 ? `${f(m / 1000)} km` : `${f(m)} m`;
}

const POSITIONAL = new Set([16, 17, 18, 19, 21, 22, 82]);

// the items a UAV flies to (a copter's take-off, 22, climbs where it stands)
export function flownTo(mission) {
  return mission.items.filter((it) => it.command !== 22 && POSITIONAL.has(it.command) && (it.lat || it.lon));
}

export function missionPoints(mission, origin) {
  return mission.items
    .filter((it) => POSITIONAL.has(it.command) && (it.lat || it.lon))
    .map((it) => metres(origin, it.lat, it.lon));
}

// The airspace over a map, in metres around its origin: the zones that apply to the base (the API's
// GeoJSON Polygon, or Point with radius_m) and a mission's own QGroundControl geoFence and rally points.
// A shape is {name, kind: "inclusion"|"exclusion", active, source: "zone"|"plan", ring} or {…, centre, radius}.
export function airspace(origin, zones = [], mission = null) {
  const at = (lat, lon) => metres(origin, lat, lon);
  const shapes = [];
  for (const z of zones) {
    const g = z.geometry || {};
    const base = { name: z.name, kind: z.kind, active: z.active !== false, source: "zone", ceiling: z.ceiling_m, floor: z.floor_m };
    if (g.type === "Polygon" && Array.isArray(g.coordinates) && g.coordinates[0]) {
      shapes.push({ ...base, ring: g.coordinates[0].map(([lon, lat]) => at(lat, lon)) });
    } else if (g.type === "Point" && z.radius_m > 0) {
      shapes.push({ ...base, centre: at(g.coordinates[1], g.coordinates[0]), radius: z.radius_m });
    }
  }
  const extras = (mission && mission.extras) || {};
  const fence = extras.geoFence || {};
  (fence.polygons || []).forEach((p, k) => {
    if (Array.isArray(p.polygon) && p.polygon.length >= 3) {
      shapes.push({ name: `plan fence polygon ${k}`, kind: p.inclusion === false ? "exclusion" : "inclusion", active: true, source: "plan",
        ring: p.polygon.map(([lat, lon]) => at(lat, lon)) });
    }
  });
  (fence.circles || []).forEach((c, k) => {
    const circle = c.circle || {};
    if (Array.isArray(circle.center) && circle.radius > 0) {
      shapes.push({ name: `plan fence circle ${k}`, kind: c.inclusion === false ? "exclusion" : "inclusion", active: true, source: "plan",
        centre: at(circle.center[0], circle.center[1]), radius: circle.radius });
    }
  });
  const rally = ((extras.rallyPoints || {}).points || []).filter((p) => Array.isArray(p) && p.length >= 2).map(([lat, lon]) => at(lat, lon));
  return { shapes, rally };
}
