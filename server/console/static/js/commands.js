// Sending a command to an asset with a confirmation, and following it to its outcome.

import { get, post } from "./api.js";
import { on } from "./live.js";
import { confirmDialog, h, notify } from "./ui.js";

const FINAL = new Set(["succeeded", "rejected", "failed", "canceled", "timed_out"]);

// asks, sends, then writes each status into `out` (an aria-live element) until a final one
export async function sendCommand(asset, name, { title, body, params = {}, out, onFinal }) {
  const ok = await confirmDialog({ title, body, confirm: title });
  if (!ok) return;
  out.textContent = `${title}: sending…`;
  let command;
  try {
    command = await post(`/assets/${asset.id}/commands`, { name, params, timeout_s: 120 });
  } catch (err) {
    out.textContent = `${title}: refused — ${err.message}`;
    return;
  }
  let done = false;
  const show = (status, reason) => {
    out.textContent = `${title}: ${status.replace("_", " ")}${reason ? ` — ${reason}` : ""}`;
    out.dataset.status = status;
  };
  show(command.status, command.reason);
  const finish = (c) => {
    if (done) return;
    done = true;
    off();
    show(c.status, c.reason);
    notify(`${asset.name}: ${title} ${c.status.replace("_", " ")}`, c.status === "succeeded" ? "" : "bad");
    if (onFinal) onFinal(c);
  };
  const off = on("command_result", (p, msg) => {
    if (msg.re !== command.id) return;
    if (FINAL.has(p.status)) finish({ status: p.status, reason: p.reason, result: p.data });
    else show(p.status, p.progress ? p.progress.message || p.progress.step : p.reason);
  });
  // the socket may be reconnecting: the command's own record is the authority
  while (!done) {
    await new Promise((r) => setTimeout(r, 1500));
    if (done) break;
    try {
      const c = await get(`/commands/${command.id}`);
      if (FINAL.has(c.status)) finish(c);
    } catch (_) { /* keep trying until the deadline answers */ }
  }
}

export function commandButton(asset, label, name, opts) {
  const out = opts.out;
  return h("button", {
    type: "button",
    class: opts.danger ? "danger" : "",
    "aria-label": `${label}: ${asset.name}`,
    onclick: () => sendCommand(asset, name, { title: label, body: opts.body, out, onFinal: opts.onFinal }),
  }, label);
}
