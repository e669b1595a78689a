// The console's shell: the session, the navigation between pages, the live-link indicator.

import { api, ApiError, current, get, onSignedOut, renew, setSession } from "./api.js";
import { follow, on, state, stop } from "./live.js";
import { clear, h, notify } from "./ui.js";

const PAGES = {
  fleet: () => import("./fleet.js"),
  runs: () => import("./runs.js"),
  missions: () => import("./missions.js"),
  history: () => import("./history.js"),
  report: () => import("./report.js"),
  replay: () => import("./replay.js"),
  account: () => import("./account.js"),
};

const main = document.getElementById("main");
let ctx = null; // {me, assets, byId, canOperate}
let cleanup = null;
let signedOutReason = "";
let keepAlive = null;
let renewTimer = null;

// renew when a quarter of the session's lifetime is left, so an open console never expires
function scheduleRenewal() {
  clearTimeout(renewTimer);
  const s = current();
  if (!s || !s.expires_at) return;
  const end = Date.parse(s.expires_at);
  const lifetime = end - (s.issued_at || Date.now());
  const wait = Math.max(1000, end - lifetime / 4 - Date.now());
  renewTimer = setTimeout(() => renew().then(scheduleRenewal, () => {}), Math.min(wait, 2 ** 31 - 1));
}

// Show `hash`: a new hash is shown by the hashchange handler, the same one here (showing it
// from both would boot and render the page twice, every request of it sent twice).
function go(hash) {
  if (location.hash === hash) show();
  else location.hash = hash;
}

function route() {
  const [name, ...args] = location.hash.replace(/^#\/?/, "").split("/");
  return { name: name || "fleet", args };
}

async function show() {
  if (cleanup) { cleanup(); cleanup = null; }
  if (!current()) return signInPage();
  if (!ctx) {
    try { await boot(); } catch (err) { if (!current()) return signInPage(); throw err; }
  }
  const { name, args } = route();
  const load = PAGES[name] || PAGES.fleet;
  for (const a of document.querySelectorAll("#nav a")) {
    const target = a.getAttribute("href").slice(2);
    const here = target === name || (target === "history" && (name === "report" || name === "replay"));
    if (here) a.setAttribute("aria-current", "page"); else a.removeAttribute("aria-current");
  }
  const page = await load();
  clear(main);
  cleanup = page.render(main, ctx, args) || null;
  main.focus({ preventScroll: true });
}

async function boot() {
  const me = await get("/auth/me");
  const assets = await get("/assets?limit=1000");
  ctx = {
    me,
    assets,
    byId: new Map(assets.map((a) => [a.id, a])),
    canOperate: me.is_superuser || me.role === "operator" || me.role === "admin",
  };
  const org = (me.memberships || []).find((m) => m.organization_id === me.organization_id);
  clear(document.getElementById("who"),
    h("a", { href: "#/account", title: "Your account and password" },
      `${me.email} · ${org ? org.organization_name : "platform"} · ${me.role || "superuser"}`),
    h("button", { type: "button", onclick: signOut }, "Sign out"));
  document.getElementById("nav").hidden = false;
  follow(assets.map((a) => a.id));
  clearInterval(keepAlive);
  // a request a minute keeps an open console's session from idling out, and notices its end
  keepAlive = setInterval(() => get("/auth/me").catch(() => {}), 60000);
  scheduleRenewal();
}

function reset() {
  ctx = null;
  stop();
  clearInterval(keepAlive);
  clearTimeout(renewTimer);
  document.getElementById("nav").hidden = true;
  clear(document.getElementById("who"));
}

async function signOut() {
  try { await api("POST", "/auth/logout"); } catch (_) { /* already over */ }
  setSession(null);
  reset();
  location.hash = "#/";
  signInPage();
}

onSignedOut((reason) => {
  signedOutReason = reason;
  reset();
  signInPage();
});

function linkIndicator() {
  const el = document.getElementById("link");
  const text = {
    live: "Live",
    connecting: "Connecting…",
    reconnecting: state.retryIn ? `Connection lost: reconnecting in ${Math.ceil(state.retryIn / 1000)} s` : "Reconnecting…",
    offline: "",
  }[state.link];
  el.textContent = text;
  el.className = `link ${state.link === "live" ? "live" : state.link === "reconnecting" ? "down" : ""}`;
  el.hidden = !text;
}
on("link", linkIndicator);

function signInPage() {
  if (cleanup) { cleanup(); cleanup = null; }
  const error = h("div", { role: "alert", class: "error" });
  const email = h("input", { id: "email", name: "email", type: "email", autocomplete: "username", required: true });
  const password = h("input", { id: "password", name: "password", type: "password", autocomplete: "current-password", required: true });
  const orgPick = h("div");
  let force = false;
  let organization = null;
  let picking = null; // the /auth/me of a session whose organisation is being chosen

  async function submit(e) {
    e.preventDefault();
    error.textContent = "";
    if (picking) {
      const choice = orgPick.querySelector("select").value;
      if (choice === picking.organization_id) {
        password.value = "";
        return go("#/fleet");
      }
      organization = choice;
      force = true; // the session just opened is replaced by one in the chosen organisation
      picking = null;
    }
    const body = { email: email.value, password: password.value, force };
    if (organization) body.organization_id = organization;
    try {
      const r = await api("POST", "/auth/login", body);
      setSession({ token: r.access_token, expires_at: r.expires_at, issued_at: Date.now() });
      const me = await get("/auth/me");
      if (!organization && (me.memberships || []).length > 1) return chooseOrganisation(me);
      password.value = "";
      signedOutReason = "";
      go(!location.hash || location.hash === "#/" ? "#/fleet" : location.hash);
    } catch (err) {
      if (!(err instanceof ApiError)) throw err;
      if (err.code === "session_active") {
        force = true;
        clear(error,
          h("p", {}, "This account already has a live session (another browser or device). " +
            "Aerobase allows one live session per account: signing in here ends the other one, " +
            "which is then told that another login took it over."),
          h("p", {}, "Press “Sign in and end the other session” to continue."));
        button.textContent = "Sign in and end the other session";
      } else if (err.code === "rate_limited") {
        error.textContent = `Too many failed sign-ins: ${err.message}`;
      } else {
        error.textContent = err.message;
      }
    }
  }

  function chooseOrganisation(me) {
    const select = h("select", { id: "org", name: "organization" },
      me.memberships.map((m) => h("option", { value: m.organization_id, selected: m.organization_id === me.organization_id },
        `${m.organization_name} (${m.role})`)));
    clear(orgPick, h("label", { for: "org" }, "Organisation"), select);
    button.textContent = "Continue";
    picking = me;
  }

  const button = h("button", { type: "submit", class: "primary" }, "Sign in");
  const form = h("form", { class: "stack", "aria-labelledby": "signin-title", onsubmit: submit },
    h("label", { for: "email" }, "E-mail"), email,
    h("label", { for: "password" }, "Password"), password,
    orgPick, button, error);
  clear(main, h("section", { class: "card signin" },
    h("h1", { id: "signin-title" }, "Sign in to Aerobase"),
    signedOutReason ? h("p", { role: "alert", class: "error" }, signedOutReason) : null,
    form));
  email.focus();
}

window.addEventListener("hashchange", () => { if (current()) show(); });
window.addEventListener("unhandledrejection", (e) => {
  const err = e.reason;
  notify(err && err.message ? err.message : String(err), "bad");
});
show();
