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
    `from ${fmt(Math.min(...vals))} to ${fmt(Math.max(...vals))} ${unit}`);
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

// track, mission: [{north, east}] in metres from the base at (0, 0); uav: {north, east} or null;
// geo: the base's {lat, lon}, for the site's map tiles when the server names a tile URL
export function trackMap({ title, track = [], mission = [], uav = null, minSpan = 60, geo = null }) {
  const W = 420, M = 28;
  const all = [{ north: 0, east: 0 }, ...track, ...mission, ...(uav ? [uav] : [])];
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
  svg.append(s("text", { x: M, y: W - 8 }, `grid ${fmt(step)} m · north up · base at the centre`));
  svg.append(s("text", { x: cx - 4, y: M - 10 }, "N"));
  if (mission.length) {
    svg.append(s("path", { d: mission.map((p, i) => `${i ? "L" : "M"}${X(p)},${Y(p)}`).join(""), class: "mission" }));
    for (const p of mission) svg.append(s("circle", { cx: X(p), cy: Y(p), r: 3, class: "wp" }));
  }
  if (track.length) {
    svg.append(s("path", { d: track.map((p, i) => `${i ? "L" : "M"}${X(p).toFixed(1)},${Y(p).toFixed(1)}`).join(""), class: "line" }));
  }
  svg.append(s("rect", { x: cx - 5, y: cy - 5, width: 10, height: 10, class: "base" }));
  if (uav) svg.append(s("circle", { cx: X(uav), cy: Y(uav), r: 5, class: "uav" }));
  const far = Math.max(0, ...track.map((p) => Math.hypot(p.north, p.east)), ...mission.map((p) => Math.hypot(p.north, p.east)));
  svg.setAttribute("aria-label",
    `${title}: ${track.length} track points, ${mission.length} mission points, ` +
    `farthest ${fmt(far)} m from the base` + (uav ? `; UAV ${fmt(uav.north)} m north, ${fmt(uav.east)} m east` : ""));
  return svg;
}
