// Where things are: the base that is the map's origin, and a mission's points in metres around it.

import { metres } from "./ui.js";

export function originOf(ctx, uav) {
  const base = uav && uav.base_id ? ctx.byId.get(uav.base_id) : ctx.assets.find((a) => a.kind === "landing_base");
  const a = base ? base.attributes || {} : {};
  if (Number.isFinite(a.latitude) && Number.isFinite(a.longitude)) return { lat: a.latitude, lon: a.longitude };
  return null;
}

const POSITIONAL = new Set([16, 17, 18, 19, 21, 22, 82]);

export function missionPoints(mission, origin) {
  return mission.items
    .filter((it) => POSITIONAL.has(it.command) && (it.lat || it.lon))
    .map((it) => metres(origin, it.lat, it.lon));
}
