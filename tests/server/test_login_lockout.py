"""Wrong passwords from anywhere cannot lock out a client that holds the right one (SECURITY.md:
"anyone on the network must not be able to lock out a user"): failures from an address where the
account has logged in count against the account at that address; elsewhere, against the
account as a whole. The limiter's tables are pruned of what no longer counts."""

from __future__ import annotations

import asyncio
import base64
import uuid
from datetime import timedelta

import httpx
from sqlalchemy import select

from assetlink.configfile import decrypt_config
from server.auth.limiter import LoginLimiter, housekeeping
from server.auth.models import KnownLoginClient, LoginFailure
from server.auth.repository import LoginFailureRepository
from server.deps import services_of
from server.kit.db import make_engine, make_sessionmaker
from server.kit.security import Passwords
from server.kit.time import utcnow
from server.kit.uow import unit_of_work
from server.organizations.repository import UserRepository
from tests.conftest import LiveServer, Tenant, auth, test_settings
from tests.metrics import value
from tests.server.test_ntrip_caster import ask, basic, v1

HOME = {"X-Forwarded-For": "192.0.2.10"}


def _login(api: httpx.Client, email: str, password: str, addr: str) -> httpx.Response:
    body = {"email": email, "password": password, "force": True}
    return api.post("/api/v1/auth/login", json=body, headers={"X-Forwarded-For": addr})


def test_wrong_passwords_from_elsewhere_do_not_lock_out_a_user_where_they_log_in(
    api, tenant: Tenant
):
    email = tenant.emails["operator"]
    assert _login(api, email, Tenant.PASSWORD, "192.0.2.10").status_code == 200
    # a guesser at other addresses: the account's limit (5), then 429
    codes = [
        _login(api, email, f"guess-{i:04d}", f"203.0.113.{i + 1}").status_code for i in range(8)
    ]
    assert codes == [401] * 5 + [429] * 3, codes
    # from where the user logs in: the right password gets in, twice (the second success must
    # not have given the guesser a new allowance)
    for _ in range(2):
        r = _login(api, email, Tenant.PASSWORD, "192.0.2.10")
        assert r.status_code == 200, r.text
        assert api.get("/api/v1/auth/me", headers=auth(r.json()["access_token"])).status_code == 200
        assert _login(api, email, "guess-9999", "203.0.113.99").status_code == 429
    # from an address the account never logged in from: the account-wide limit stands
    assert _login(api, email, Tenant.PASSWORD, "198.51.100.20").status_code == 429


def test_a_known_address_has_a_limit_of_its_own(api, tenant: Tenant):
    email = tenant.emails["viewer"]
    assert _login(api, email, Tenant.PASSWORD, "192.0.2.11").status_code == 200
    codes = [_login(api, email, f"typo-{i:04d}", "192.0.2.11").status_code for i in range(7)]
    assert codes == [401] * 5 + [429] * 2, codes
    r = _login(api, email, Tenant.PASSWORD, "192.0.2.11")
    assert r.status_code == 429 and int(r.headers["Retry-After"]) > 0
    # those failures were the address's, not the account's: elsewhere the user gets in
    assert _login(api, email, Tenant.PASSWORD, "192.0.2.12").status_code == 200


def test_a_stale_password_retried_is_not_counted_again(api, tenant: Tenant):
    """A script (or a rover) retrying an old password from where the user logs in: one failure,
    not one per try, so the user at that address is not shut out by it."""
    email = tenant.emails["admin"]
    assert _login(api, email, Tenant.PASSWORD, "192.0.2.13").status_code == 200
    codes = [_login(api, email, "the-old-password", "192.0.2.13").status_code for _ in range(12)]
    assert codes == [401] * 12, codes
    assert _login(api, email, Tenant.PASSWORD, "192.0.2.13").status_code == 200
    # distinct wrong passwords from there are each counted (the success cleared the stale one's)
    codes = [_login(api, email, f"typo-{i:04d}", "192.0.2.13").status_code for i in range(6)]
    assert codes == [401] * 5 + [429], codes


def test_the_same_wrong_password_from_other_addresses_is_counted(api, tenant: Tenant):
    """The memory of wrong passwords is per address: a guesser learns nothing of other people's
    tries from it, and each address's try counts."""
    email = tenant.emails["viewer"]
    codes = [
        _login(api, email, "password-one", f"203.0.113.{i + 100}").status_code for i in range(6)
    ]
    assert codes == [401] * 5 + [429], codes
    assert _login(api, email, Tenant.PASSWORD, "203.0.113.120").status_code == 429


async def test_a_password_that_failed_is_checked_again_once_the_account_hash_changes(
    database_url, api, tenant: Tenant
):
    email = tenant.emails["operator"]
    assert _login(api, email, "the-next-password", "192.0.2.14").status_code == 401
    engine = make_engine(database_url)
    try:  # as an administrator resetting the password (the hash is any argon2id one)
        async with unit_of_work(make_sessionmaker(engine)) as uow:
            user = await UserRepository(uow.db).by_email(email)
            assert user is not None
            user.password_hash = Passwords(time_cost=1, memory_kib=8192, parallelism=1).hash(
                "the-next-password"
            )
    finally:
        await engine.dispose()
    r = _login(api, email, "the-next-password", "192.0.2.14")
    assert r.status_code == 200, r.text


async def test_a_rover_keeps_its_corrections_while_its_account_is_guessed_at(
    database_url, api, superuser_email
):
    tenant = Tenant(api, superuser_email, "rover-lockout")
    settings = test_settings(database_url, ntrip_port=0, ntrip_proxy_protocol=True)
    server = LiveServer(settings).start()
    try:
        caster = services_of(server.app).ntrip
        assert caster is not None

        email = tenant.emails["viewer"]

        async def rover(address: str, password: str, user: str = email) -> bytes:
            proxy_line = f"PROXY TCP4 {address} 127.0.0.1 40001 2101\r\n"
            return await ask(caster.port, proxy_line + v1("/", basic(user, password)))

        assert (await rover("198.51.100.30", Tenant.PASSWORD)).startswith(b"SOURCETABLE 200 OK")
        # the guesser spells the account in every case: one account, one limit, all the same
        spellings = [email, email.upper(), email.title(), email.capitalize()]
        answers = [
            await rover(f"203.0.113.{i + 40}", f"guess-{i}", spellings[i % 4]) for i in range(7)
        ]
        assert all(a.startswith(b"HTTP/1.0 401") for a in answers)
        # the rover reconnecting from its address gets in; a new one elsewhere does not
        assert (await rover("198.51.100.30", Tenant.PASSWORD)).startswith(b"SOURCETABLE 200 OK")
        assert (await rover("198.51.100.31", Tenant.PASSWORD)).startswith(b"HTTP/1.0 401")
        # a misconfigured rover beside it (one NAT) retries a stale password: not counted again
        for _ in range(10):
            assert (await rover("198.51.100.30", "stale")).startswith(b"HTTP/1.0 401")
        assert (await rover("198.51.100.30", Tenant.PASSWORD)).startswith(b"SOURCETABLE 200 OK")
    finally:
        await asyncio.to_thread(server.stop)


async def test_housekeeping_drops_what_no_longer_counts(database_url):
    settings = test_settings(database_url, login_window_s=600, login_known_client_days=30)
    engine = make_engine(database_url)
    try:
        sessionmaker = make_sessionmaker(engine)
        tag = uuid.uuid4().hex[:8]
        now = utcnow()
        async with unit_of_work(sessionmaker) as uow:
            repo = LoginFailureRepository(uow.db)
            await repo.add([f"account:old-{tag}"], now - timedelta(seconds=601))
            await repo.add([f"account:new-{tag}"], now - timedelta(seconds=30))
            await repo.remember(f"old-{tag}", "192.0.2.1", now - timedelta(days=31))
            await repo.remember(f"new-{tag}", "192.0.2.1", now - timedelta(days=29))
        assert await housekeeping(sessionmaker, settings) >= 2
        async with sessionmaker() as db:
            failures = select(LoginFailure.key).where(LoginFailure.key.endswith(tag))
            keys = set((await db.scalars(failures)).all())
            clients = select(KnownLoginClient.account_key).where(
                KnownLoginClient.account_key.endswith(tag)
            )
            known = set((await db.scalars(clients)).all())
        assert f"account:old-{tag}" not in keys and f"account:new-{tag}" in keys
        assert f"old-{tag}" not in known and f"new-{tag}" in known
        # what is left still counts: the known client is known, the failure in the window
        limiter = LoginLimiter(sessionmaker, settings)
        attempt = await limiter.admit(f"new-{tag}", "192.0.2.1", utcnow())
        assert attempt.account == f"account:new-{tag}|at:192.0.2.1"
        attempt = await limiter.admit(f"old-{tag}", "192.0.2.1", utcnow())
        assert attempt.account == f"account:old-{tag}"
    finally:
        await engine.dispose()


def test_password_checks_are_counted_on_metrics_by_door_and_outcome(api, tenant: Tenant):
    """What an operator alerts on (a guesser at work, rovers with stale passwords): every check
    of a password or secret, by door and outcome, on `/metrics`."""

    def counts() -> dict[tuple[str, str], float]:
        text = api.get("/metrics").text
        doors = ("user", "asset", "password_change")
        outcomes = ("ok", "wrong", "repeated", "limited")
        return {
            (d, o): value(text, "aerobase_logins_total", door=d, outcome=o)
            for d in doors
            for o in outcomes
        }

    email, where = tenant.emails["viewer"], "192.0.2.77"
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    before = counts()
    assert _login(api, email, Tenant.PASSWORD, where).status_code == 200  # user ok
    assert _login(api, email, "wrong-0000", where).status_code == 401  # user wrong
    assert _login(api, email, "wrong-0000", where).status_code == 401  # user repeated
    for i in range(1, 5):
        assert _login(api, email, f"wrong-{i:04d}", where).status_code == 401  # user wrong x4
    assert _login(api, email, "wrong-0005", where).status_code == 429  # user limited
    r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": "not-it"})
    assert r.status_code == 401  # asset wrong
    r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    assert r.status_code == 200  # asset ok
    body = {"current_password": "not-mine-at-all", "new_password": "x" * 12}
    r = api.post("/api/v1/auth/password", json=body, headers=tenant.h("operator"))
    assert r.status_code == 422  # password_change wrong
    after = counts()
    delta = {k: after[k] - before[k] for k in after if after[k] != before[k]}
    assert delta == {
        ("user", "ok"): 1,
        ("user", "wrong"): 5,
        ("user", "repeated"): 1,
        ("user", "limited"): 1,
        ("asset", "wrong"): 1,
        ("asset", "ok"): 1,
        ("password_change", "wrong"): 1,
    }, delta
