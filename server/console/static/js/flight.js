// What a run's report and replay share: loading the run's stored telemetry and deriving series.

import { get } from "./api.js";
import { originOf } from "./geo.js";
import { metres } from "./ui.js";

export async function loadFlight(ctx, runId) {
  const report = await get(`/runs/${runId}/report`);
  const run = report.run;
  const start = run.created_at;
  const end = run.finished_at || new Date().toISOString();
  const window = `start=${encodeURIComponent(start)}&end=${encodeURIComponent(end)}&limit=100000`;
  const [mission, motion] = await Promise.all([
    get(`/missions/${run.mission_id}`).catch(() => null),
    get(`/assets/${run.uav_id}/telemetry?${window}&fields=velocity.north_m_s,velocity.east_m_s,flight_mode,landed_state`),
  ]);
  const uav = ctx.byId.get(run.uav_id);
  const track = report.track.map((r) => ({ ...r, t: Date.parse(r.ts) }));
  let origin = originOf(ctx, uav);
  if (!origin && track.length) origin = { lat: track[0]["position.lat"], lon: track[0]["position.lon"] };
  for (const p of track) Object.assign(p, origin ? metres(origin, p["position.lat"], p["position.lon"]) : {});
  const speed = motion
    .filter((r) => Number.isFinite(r["velocity.north_m_s"]))
    .map((r) => ({ t: Date.parse(r.ts), v: Math.hypot(r["velocity.north_m_s"], r["velocity.east_m_s"]) }));
  return { report, run, mission, track, origin, speed, motion, t0: Date.parse(start), t1: Date.parse(end) };
}

// when the run entered a state (ms), from its timeline
export function entered(run, state) {
  const t = (run.timeline || []).find((x) => x.to_state === state);
  return t ? Date.parse(t.at) : null;
}
