// Plots drawn locally as SVG: time series and the track in metres around the base.

const NS = "http://www.w3.org/2000/svg";

function s(tag, attrs = {}, text) {
  const el = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (text !== undefined) el.textContent = text;
  return el;
}

function niceStep(span, count) {
  const raw = span / Math.max(1, count);
  const mag = 10 ** Math.floor(Math.log10(raw || 1));
  for (const m of [1, 2, 5, 10]) if (raw <= m * mag) return m * mag;
  return 10 * mag;
}

function fmt(v) {
  const a = Math.abs(v);
  return a >= 100 || v === 0 ? v.toFixed(0) : a >= 10 ? v.toFixed(1) : v.toFixed(2);
}

// points: [{t: ms, v: number}]; returns an <svg role="img"> with a text summary as its label
export function lineChart({ title, unit, points, t0, t1, cursor = null, marks = [] }) {
  const W = 520, H = 220, L = 48, R = 12, T = 12, B = 30;
  const pts = points.filter((p) => Number.isFinite(p.v) && Number.isFinite(p.t));
  const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, class: "plot", role: "img" });
  if (!pts.length) {
    svg.setAttribute("aria-label", `${title}: no samples`);
    svg.append(s("text", { x: W / 2, y: H / 2, "text-anchor": "middle" }, "no samples"));
    return svg;
  }
  const start = t0 ?? pts[0].t, end = Math.max(t1 ?? pts[pts.length - 1].t, start + 1000);
  let lo = Math.min(...pts.map((p) => p.v)), hi = Math.max(...pts.map((p) => p.v));
  if (hi - lo < 1e-6) { lo -= 1; hi += 1; }
  const pad = (hi - lo) * 0.08; lo -= pad; hi += pad;
  const x = (t) => L + ((t - start) / (end - start)) * (W - L - R);
  const y = (v) => T + (1 - (v - lo) / (hi - lo)) * (H - T - B);
  const step = niceStep(hi - lo, 5);
  for (let v = Math.ceil(lo / step) * step; v <= hi; v += step) {
    svg.append(s("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), class: "gridl" }));
    svg.append(s("text", { x: L - 4, y: y(v) + 4, "text-anchor": "end" }, fmt(v)));
  }
  const tstep = niceStep((end - start) / 1000, 6) * 1000;
  for (let t = start; t <= end; t += tstep) {
    svg.append(s("text", { x: x(t), y: H - 10, "text-anchor": "middle" }, `${Math.round((t - start) / 1000)} s`));
  }
  svg.append(s("line", { x1: L, x2: L, y1: T, y2: H - B, class: "axis" }));
  svg.append(s("line", { x1: L, x2: W - R, y1: H - B, y2: H - B, class: "axis" }));
  for (const m of marks) {
    svg.append(s("line", { x1: x(m.t), x2: x(m.t), y1: T, y2: H - B, class: "gridl", "stroke-dasharray": "3 3" }));
    svg.append(s("text", { x: x(m.t) + 2, y: T + 10 }, m.label));
  }
  const d = pts.map((p, i) => `${i ? "L" : "M"}${x(p.t).toFixed(1)},${y(p.v).toFixed(1)}`).join("");
  svg.append(s("path", { d, class: "line" }));
  svg.append(s("text", { x: L + 4, y: T + 10, "font-weight": "600" }, unit));
  if (cursor !== null) svg.append(s("line", { x1: x(cursor), x2: x(cursor), y1: T, y2: H - B, class: "cursor" }));
  const vals = pts.map((p) => p.v);
  svg.setAttribute("aria-label",
    `${title}: ${pts.length} samples over ${Math.round((end - start) / 1000)} s, ` +
    `from ${fmt(Math.min(...vals))} to ${fmt(Math.max(...vals))} ${unit}, ending at ${fmt(vals[vals.length - 1])} ${unit}`);
  return svg;
}

const TILES = document.querySelector('meta[name="aerobase-map-tiles"]');
const TILE_URL = TILES ? TILES.getAttribute("content") : null;
const R = 6371008.8;

function toLatLon(geo, north, east) {
  const lat = geo.lat + (north / R) * 180 / Math.PI;
  const lon = geo.lon + (east / (R * Math.cos(geo.lat * Math.PI / 180))) * 180 / Math.PI;
  return { lat, lon };
}

// the site's map tiles (AEROBASE_MAP_TILE_URL, web mercator) under a square of `span` metres
function tiles(geo, span, X, Y, W) {
  const group = s("g", { class: "tiles", "aria-hidden": "true" });
  const perPixel = span / W; // metres per drawn unit; tiles are 256 px
  const z = Math.max(0, Math.min(19, Math.round(Math.log2((156543.03 * Math.cos(geo.lat * Math.PI / 180)) / perPixel))));
  const n = 2 ** z;
  const tx = (lon) => Math.floor(((lon + 180) / 360) * n);
  const ty = (lat) => {
    const r = lat * Math.PI / 180;
    return Math.floor(((1 - Math.log(Math.tan(r) + 1 / Math.cos(r)) / Math.PI) / 2) * n);
  };
  const lonOf = (x) => (x / n) * 360 - 180;
  const latOf = (y) => Math.atan(Math.sinh(Math.PI * (1 - (2 * y) / n))) * 180 / Math.PI;
  const nw = toLatLon(geo, span / 2, -span / 2), se = toLatLon(geo, -span / 2, span / 2);
  const [x0, x1, y0, y1] = [tx(nw.lon), tx(se.lon), ty(nw.lat), ty(se.lat)];
  if ((x1 - x0 + 1) * (y1 - y0 + 1) > 64) return group;
  const m = (lat, lon) => {
    const north = ((lat - geo.lat) * Math.PI / 180) * R;
    const east = ((lon - geo.lon) * Math.PI / 180) * R * Math.cos(geo.lat * Math.PI / 180);
    return { north, east };
  };
  for (let x = x0; x <= x1; x++) {
    for (let y = y0; y <= y1; y++) {
      const a = m(latOf(y), lonOf(x)), b = m(latOf(y + 1), lonOf(x + 1));
      const href = TILE_URL.replace("{z}", z).replace("{x}", x).replace("{y}", y);
      group.append(s("image", { href, x: X(a), y: Y(a), width: X(b) - X(a), height: Y(b) - Y(a), preserveAspectRatio: "none" }));
    }
  }
  return group;
}

// what a zone is called, for the map's accessible name and its shapes' tooltips
function zoneLabel(z) {
  const what = z.source === "plan" ? `${z.name} (${z.kind})` : `${z.kind} zone '${z.name}'`;
  const heights = z.floor != null || z.ceiling != null ? `, ${z.floor != null ? `floor ${+z.floor.toFixed(1)} m` : "from the ground"} to ${z.ceiling != null ? `ceiling ${+z.ceiling.toFixed(1)} m` : "no ceiling"}` : "";
  return `${what}${z.active ? "" : " (inactive now)"}${heights}`;
}

// the airspace under the track: inclusion outlined, exclusion filled and hatched, inactive dimmed
// (zones beyond 5 km of the base are drawn but do not widen the map)
function airspaceLayer(svg, { shapes, rally }, X, Y, scale, clip) {
  const hatch = `hatch-${Math.random().toString(36).slice(2)}`;
  const pattern = s("pattern", { id: hatch, width: 6, height: 6, patternUnits: "userSpaceOnUse", patternTransform: "rotate(45)" });
  pattern.append(s("line", { x1: 0, y1: 0, x2: 0, y2: 6, class: "hatch" }));
  const defs = s("defs");
  defs.append(pattern);
  svg.append(defs);
  const layer = s("g", { class: "airspace", "clip-path": `url(#${clip})` });
  for (const z of [...shapes].sort((a, b) => (a.kind === "inclusion" ? -1 : 1) - (b.kind === "inclusion" ? -1 : 1))) {
    const cls = `zone ${z.kind}${z.source === "plan" ? " plan" : ""}${z.active ? "" : " inactive"}`;
    const attrs = { class: cls, fill: z.kind === "exclusion" ? `url(#${hatch})` : "none" };
    const el = z.ring
      ? s("path", { ...attrs, d: z.ring.map((p, i) => `${i ? "L" : "M"}${X(p).toFixed(1)},${Y(p).toFixed(1)}`).join("") + "Z" })
      : s("circle", { ...attrs, cx: X(z.centre), cy: Y(z.centre), r: z.radius * scale });
    el.append(s("title", {}, zoneLabel(z)));
    layer.append(el);
  }
  for (const p of rally) {
    const g = s("g", { class: "rally" });
    g.append(s("title", {}, `rally point ${fmt(p.north)} m north, ${fmt(p.east)} m east`));
    g.append(s("path", { d: `M${X(p)},${Y(p) - 6}L${X(p) + 5},${Y(p) + 3}L${X(p) - 5},${Y(p) + 3}Z` }));
    layer.append(g);
  }
  svg.append(layer);
  return hatch;
}

// a legend of what is drawn, in the map's top left corner
function legend(svg, entries, M, hatch) {
  if (!entries.length) return;
  const g = s("g", { class: "legend", "aria-hidden": "true" });
  g.append(s("rect", { x: M + 4, y: M + 4, width: 172, height: entries.length * 15 + 6, class: "legend-box" }));
  entries.forEach(([cls, label], i) => {
    const y = M + 10 + i * 15;
    g.append(cls === "rally"
      ? s("path", { d: `M${M + 16},${y}L${M + 21},${y + 9}L${M + 11},${y + 9}Z`, class: "rally-mark" })
      : s("rect", { x: M + 9, y, width: 14, height: 9, class: cls, fill: cls.includes("exclusion") ? `url(#${hatch})` : "none" }));
    g.append(s("text", { x: M + 28, y: y + 8 }, label));
  });
  svg.append(g);
}

// track, mission: [{north, east}] in metres from the base at (0, 0); uav: {north, east} or null;
// geo: the base's {lat, lon}, for the site's map tiles when the server names a tile URL;
// airspace: {shapes, rally} from geo.js's airspace(), drawn under the track
// `centre`: what stands at the map's origin, "base" (drawn as the base) or "home" (a mission's planned home,
// drawn hollow: the base's position is unknown); `legs`: draw the flights base -> first item and last item -> base.
export function trackMap({ title, track = [], mission = [], uav = null, minSpan = 60, geo = null, airspace = null, centre = "base", legs = false }) {
  const W = 420, M = 28;
  const shapes = airspace ? airspace.shapes : [], rally = airspace ? airspace.rally : [];
  const zonePoints = shapes.flatMap((z) => z.ring || [
    { north: z.centre.north + z.radius, east: z.centre.east + z.radius }, { north: z.centre.north - z.radius, east: z.centre.east - z.radius }]);
  const near = [...zonePoints, ...rally].filter((p) => Math.hypot(p.north, p.east) <= 5000);
  const all = [{ north: 0, east: 0 }, ...track, ...mission, ...(uav ? [uav] : []), ...near];
  const span = Math.max(minSpan, ...all.map((p) => Math.max(Math.abs(p.north), Math.abs(p.east)) * 2.2));
  const scale = (W - 2 * M) / span;
  const cx = W / 2, cy = W / 2;
  const X = (p) => cx + p.east * scale, Y = (p) => cy - p.north * scale;
  const svg = s("svg", { viewBox: `0 0 ${W} ${W}`, class: "plot", role: "img" });
  if (TILE_URL && geo) {
    const clip = `clip-${Math.random().toString(36).slice(2)}`;
    svg.append(s("clipPath", { id: clip }, undefined));
    svg.lastChild.append(s("rect", { x: M, y: M, width: W - 2 * M, height: W - 2 * M }));
    const layer = tiles(geo, span, X, Y, W - 2 * M);
    layer.setAttribute("clip-path", `url(#${clip})`);
    svg.append(layer);
  }
  const step = niceStep(span, 6);
  for (let m = -Math.floor(span / 2 / step) * step; m <= span / 2; m += step) {
    svg.append(s("line", { x1: M, x2: W - M, y1: cy - m * scale, y2: cy - m * scale, class: "gridl" }));
    svg.append(s("line", { y1: M, y2: W - M, x1: cx + m * scale, x2: cx + m * scale, class: "gridl" }));
  }
  const atCentre = centre === "base" ? "base at the centre" : "the mission's home at the centre (base position unknown)";
  svg.append(s("text", { x: M, y: W - 8 }, `grid ${fmt(step)} m · north up · ${atCentre}`));
  svg.append(s("text", { x: cx - 4, y: M - 10 }, "N"));
  let hatch = null;
  if (shapes.length || rally.length) {
    const clip = `clip-${Math.random().toString(36).slice(2)}`;
    svg.append(s("clipPath", { id: clip }));
    svg.lastChild.append(s("rect", { x: M, y: M, width: W - 2 * M, height: W - 2 * M }));
    hatch = airspaceLayer(svg, { shapes, rally }, X, Y, scale, clip);
  }
  if (mission.length && legs) {
    const first = mission[0], last = mission[mission.length - 1];
    svg.append(s("path", { d: `M${cx},${cy}L${X(first)},${Y(first)}M${X(last)},${Y(last)}L${cx},${cy}`, class: "leg" }));
  }
  if (mission.length) {
    svg.append(s("path", { d: mission.map((p, i) => `${i ? "L" : "M"}${X(p)},${Y(p)}`).join(""), class: "mission" }));
    for (const p of mission) svg.append(s("circle", { cx: X(p), cy: Y(p), r: 3, class: "wp" }));
  }
  if (track.length) {
    svg.append(s("path", { d: track.map((p, i) => `${i ? "L" : "M"}${X(p).toFixed(1)},${Y(p).toFixed(1)}`).join(""), class: "line" }));
  }
  svg.append(s("rect", { x: cx - 5, y: cy - 5, width: 10, height: 10, class: centre === "base" ? "base" : "home" }));
  if (uav) svg.append(s("circle", { cx: X(uav), cy: Y(uav), r: 5, class: "uav" }));
  const kinds = [
    [shapes.some((z) => z.kind === "inclusion" && z.source === "zone" && z.active), "zone inclusion", "inclusion zone (stay inside)"],
    [shapes.some((z) => z.kind === "exclusion" && z.source === "zone" && z.active), "zone exclusion", "exclusion zone (keep out)"],
    [shapes.some((z) => z.source === "plan"), "zone inclusion plan", "the plan's own fence"],
    [shapes.some((z) => !z.active), "zone inclusion inactive", "inactive now (dimmed)"],
    [rally.length > 0, "rally", "rally point"],
  ];
  legend(svg, kinds.filter(([on]) => on).map(([, cls, label]) => [cls, label]), M, hatch);
  const far = Math.max(0, ...track.map((p) => Math.hypot(p.north, p.east)), ...mission.map((p) => Math.hypot(p.north, p.east)));
  const zones = shapes.length ? `; airspace: ${shapes.map(zoneLabel).join("; ")}` : "";
  svg.setAttribute("aria-label",
    `${title}: ${track.length} track points, ${mission.length} mission points, ` +
    `farthest ${fmt(far)} m from the ${centre === "base" ? "base" : "mission's home"}` + (uav ? `; UAV ${fmt(uav.north)} m north, ${fmt(uav.east)} m east` : "") +
    zones + (rally.length ? `; ${rally.length} rally point${rally.length > 1 ? "s" : ""}` : ""));
  return svg;
}
