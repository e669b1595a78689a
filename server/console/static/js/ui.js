// Small DOM helpers shared by the pages: element building, formatting, notices, confirmation.

export function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined || v === false) continue;
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (k === "class") el.className = v;
    else if (k === "text") el.textContent = v;
    else el.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : String(c));
  }
  return el;
}

export function clear(el, ...children) {
  el.replaceChildren(...children.flat().filter((c) => c !== null && c !== undefined && c !== false));
  return el;
}

export function num(v, digits = 1, unit = "") {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  return `${Number(v).toFixed(digits)}${unit ? " " + unit : ""}`;
}

export function when(iso) {
  if (!iso) return "–";
  const d = new Date(iso);
  return d.toLocaleString(undefined, { dateStyle: "short", timeStyle: "medium" });
}

export function clock(iso) {
  if (!iso) return "–";
  return new Date(iso).toLocaleTimeString(undefined, { hour12: false });
}

export function ago(ms) {
  if (ms === null || ms === undefined) return "never";
  const s = ms / 1000;
  if (s < 60) return `${s.toFixed(s < 10 ? 1 : 0)} s ago`;
  if (s < 3600) return `${Math.round(s / 60)} min ago`;
  return `${Math.round(s / 3600)} h ago`;
}

export function badge(text, tone = "") {
  return h("span", { class: `badge ${tone}` }, text);
}

export function notify(message, tone = "") {
  const box = document.getElementById("notice");
  const p = h("p", { class: tone }, message);
  box.append(p);
  setTimeout(() => p.remove(), 7000);
}

// a modal confirmation: resolves with the values of its inputs, or null when cancelled
export function confirmDialog({ title, body, confirm, danger = false, inputs = [] }) {
  return new Promise((resolve) => {
    const id = `dlg-${Math.random().toString(36).slice(2)}`;
    const fields = inputs.map((f) =>
      h("label", { class: "field" }, f.label, h("input", { name: f.name, value: f.value || "", type: "text" })),
    );
    const dlg = h("dialog", { "aria-labelledby": id, "aria-modal": "true" },
      h("form", { method: "dialog", class: "stack" },
        h("h2", { id }, title),
        h("p", {}, body),
        ...fields,
        h("div", { class: "actions" },
          h("button", { value: "cancel", type: "submit" }, "Cancel"),
          h("button", { value: "ok", type: "submit", class: danger ? "danger" : "primary" }, confirm))));
    document.body.append(dlg);
    dlg.addEventListener("close", () => {
      const ok = dlg.returnValue === "ok";
      const values = {};
      for (const input of dlg.querySelectorAll("input")) values[input.name] = input.value;
      dlg.remove();
      resolve(ok ? values : null);
    });
    dlg.showModal();
  });
}

// flatten a nested telemetry payload into the dotted names the REST API uses
export function flatten(obj, prefix = "", out = {}) {
  for (const [k, v] of Object.entries(obj || {})) {
    const key = prefix ? `${prefix}.${k}` : k;
    if (v && typeof v === "object" && !Array.isArray(v)) flatten(v, key, out);
    else out[key] = v;
  }
  return out;
}

// metres north/east of an origin (equirectangular; fine over a site of a few km)
export function metres(origin, lat, lon) {
  const r = 6371008.8;
  const north = ((lat - origin.lat) * Math.PI / 180) * r;
  const east = ((lon - origin.lon) * Math.PI / 180) * r * Math.cos(origin.lat * Math.PI / 180);
  return { north, east };
}
