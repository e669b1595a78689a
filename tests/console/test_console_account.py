"""The console's account page in Debian's Chromium: a user changes their password there, told in
words what went wrong when it does not, and signs in with the new one afterwards."""

from __future__ import annotations

import asyncio

import pytest

from tests.conftest import Tenant, login
from tests.console.browser import open_page, shot, sign_in

pytestmark = pytest.mark.slow  # a browser: not in the fast lane


async def test_a_user_changes_their_password_on_the_account_page(
    live_server, api, superuser_email, browser
):
    from playwright.async_api import expect

    tenant = await asyncio.to_thread(Tenant, api, superuser_email, "account")
    email = tenant.emails["viewer"]
    page, traffic = await open_page(browser, live_server.url + "/")
    await sign_in(page, email, Tenant.PASSWORD)
    await page.get_by_role("banner").get_by_role("link", name=email).click()
    await expect(page.get_by_role("heading", name="Account", exact=True)).to_be_visible()
    current = page.get_by_label("Current password")
    new, again = page.get_by_label("New password (12"), page.get_by_label("New password again")
    change = page.get_by_role("button", name="Change password")
    alert = page.get_by_role("alert")

    await current.fill(Tenant.PASSWORD)
    await new.fill("a-new-console-password")
    await again.fill("a-new-console-passwort")
    await change.click()
    await expect(alert).to_have_text("The new passwords differ.")

    await current.fill("not-my-password")
    await again.fill("a-new-console-password")
    await change.click()
    await expect(alert).to_have_text("The current password is wrong.")

    await current.fill(Tenant.PASSWORD)
    await change.click()
    notice = page.locator("#notice").filter(has_text="Password changed.")
    await expect(notice).to_be_visible()
    await expect(current).to_have_value("")  # the form is emptied
    await shot(page, "account-password-changed")
    # the console's session goes on; the new password signs in, the old one no more
    await page.get_by_role("link", name="Fleet").click()
    await expect(page.get_by_role("heading", name="Fleet", exact=True)).to_be_visible()
    r = await asyncio.to_thread(
        api.post, "/api/v1/auth/login", json={"email": email, "password": Tenant.PASSWORD}
    )
    assert r.status_code == 401
    await asyncio.to_thread(login, api, email, "a-new-console-password", force=True)
    assert traffic.errors == [] and traffic.off_origin(live_server.url) == []
    await page.context.close()
