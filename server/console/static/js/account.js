// Account: who is signed in, and changing one's own password (POST /auth/password).

import { api, ApiError } from "./api.js";
import { clear, h, notify } from "./ui.js";

export function render(main, ctx) {
  const field = (id, label, autocomplete) => [
    h("label", { for: id }, label),
    h("input", { id, name: id, type: "password", autocomplete, required: true, minlength: id === "current" ? 1 : 12 }),
  ];
  const error = h("div", { role: "alert", class: "error" });
  const button = h("button", { type: "submit", class: "primary" }, "Change password");
  const form = h("form", { class: "stack", "aria-labelledby": "password-title", onsubmit: submit },
    ...field("current", "Current password", "current-password"),
    ...field("new", "New password (12 characters or more)", "new-password"),
    ...field("repeat", "New password again", "new-password"),
    button, error);
  const value = (id) => form.querySelector(`#${id}`).value;

  async function submit(e) {
    e.preventDefault();
    error.textContent = "";
    if (value("new") !== value("repeat")) {
      error.textContent = "The new passwords differ.";
      return;
    }
    button.disabled = true;
    try {
      await api("POST", "/auth/password", { current_password: value("current"), new_password: value("new") });
      form.reset();
      notify("Password changed. Your other sessions have ended; this one goes on.", "good");
    } catch (err) {
      if (!(err instanceof ApiError)) throw err;
      error.textContent = {
        wrong_password: "The current password is wrong.",
        same_password: "The new password is the current one.",
        rate_limited: `Too many wrong passwords: ${err.message}`,
      }[err.code] || err.message;
    } finally {
      button.disabled = false;
    }
  }

  const me = ctx.me;
  clear(main, h("h1", {}, "Account"),
    h("section", { class: "card", "aria-labelledby": "who-title" },
      h("h2", { id: "who-title" }, "Signed in as"),
      h("p", {}, `${me.email || me.name} · ${me.role || "superuser"}`)),
    me.kind === "user"
      ? h("section", { class: "card", "aria-labelledby": "password-title" },
        h("h2", { id: "password-title" }, "Change password"),
        h("p", {}, "Your other sessions end, and rovers using the old password lose their RTK corrections at their next check."),
        form)
      : null);
}
