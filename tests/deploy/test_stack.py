"""docker-compose.yml started as docs/operations.md's "docker compose up" tells an operator, in containers:
the images build, `migrate` runs once, both replicas become healthy behind nginx, the first user
is made with `docker-compose run`, the demo profile's simulated site connects through the proxy
and flies a whole run, which the console in Debian's Chromium follows live through the proxy, a
rover gets the base's corrections on the NTRIP port, and stopping a replica is graceful while the
other goes on serving (tests/deploy/docker_stack.py says how the
images are built on a machine that reaches no registry)."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import re
import socket
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
import pytest

from aerobase.ports import free_port
from asset_agent.video.rtp import RtpPublisher
from asset_agent.video.source import CameraTrack
from assetlink.configfile import decrypt_config
from tests.conftest import SUPERUSER_PASSWORD, Tenant
from tests.console.browser import launch, open_page, shot, sign_in
from tests.deploy.docker_stack import Stack, base_image, docker_daemon, run
from tests.e2e.harness import mission_items
from tests.polling import eventually, wait_for
from tests.video.netns.janus_cases import JanusViewer
from tests.video.peers import pattern

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]

ROOT_EMAIL = "root@stack.test"  # made by `admin create-superuser` with SUPERUSER_PASSWORD
ASSET_PASSWORD = "stack-asset-password-1"
RTCM3_PREAMBLE = 0xD3


@dataclass
class Site:
    """The running stack and where an operator reaches it."""

    stack: Stack
    url: str  # the proxy: AEROBASE_PUBLIC_URL
    ntrip_port: int  # the proxy's caster port
    assets: Path  # where the demo profile's daemons read their asset files


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Site]:
    """The stack built and up (without the demo profile), torn down with its volumes after."""
    tmp = tmp_path_factory.mktemp("stack")
    assets = tmp / "assets"
    assets.mkdir()
    # docs/operations.md step 7 saves the asset files in deploy/demo/assets; here they go to this test's folder
    override = tmp / "demo-assets.yml"
    mount = f"      - {assets}:/run/aerobase:ro\n"
    override.write_text(
        "services:\n"
        + "".join(f"  {svc}:\n    volumes:\n{mount}" for svc in ("base-station", "agent"))
    )
    port = free_port()
    env = {
        "AEROBASE_PUBLIC_URL": f"http://127.0.0.1:{port}",
        "AEROBASE_HTTP_PORT": str(port),
        "AEROBASE_NTRIP_PUBLIC_PORT": str(free_port()),
        "POSTGRES_PASSWORD": "stack-pg-" + uuid.uuid4().hex[:12],
        "REDIS_PASSWORD": "stack-redis-" + uuid.uuid4().hex[:12],
        "AEROBASE_LOG_LEVEL": "INFO",
        "AEROBASE_TELEMETRY_RETENTION_DAYS": "90",
        "MEDIA_PUBLIC_IP": "127.0.0.1",
        "TURN_SECRET": "stack-turn-" + uuid.uuid4().hex[:12],
        # relay ports below Linux's ephemeral range (32768-60999): Docker does not start a
        # container while a host socket holds one of its published ports, and the default range
        # lies within it, where test_media's coturn relays and any test's outgoing UDP can bind
        "TURN_MIN_PORT": "30100",
        "TURN_MAX_PORT": "30140",
        "AEROBASE_ASSET_PASSWORD": ASSET_PASSWORD,
    }
    with docker_daemon(tmp / "dockerd.log"):
        base_image()
        s = Stack(f"aerobase-test-{uuid.uuid4().hex[:8]}", env, [override])
        s.compose("build", timeout=1500)  # docs/operations.md step 2
        try:
            s.compose("up", "-d", "--no-build", timeout=600)  # step 3
            yield Site(
                s, env["AEROBASE_PUBLIC_URL"], int(env["AEROBASE_NTRIP_PUBLIC_PORT"]), assets
            )
        finally:
            s.down()


def _post(api: httpx.Client, path: str, h: dict[str, str], body: dict[str, Any]) -> Any:
    r = api.post(path, json=body, headers=h)
    assert r.status_code == 201, f"{path}: {r.status_code} {r.text}"
    return r.json()


def _replicas_answer(stack: Stack, api: httpx.Client) -> None:
    """Requests through the proxy reach both replicas: each request id shows in one replica's
    access log."""
    ids = []
    for _ in range(8):
        r = api.get("/api/ready")
        assert r.status_code == 200, r.text
        assert r.json()["checks"] == {
            "database": "ok",
            "broker": "ok",
            "influxdb": "ok",
            "janus": "ok",
        }
        ids.append(r.headers["x-request-id"])
    seen = {
        svc: {i for i in ids if i in stack.compose("logs", "--no-color", svc).stdout}
        for svc in ("server-1", "server-2")
    }
    assert seen["server-1"] and seen["server-2"], seen
    assert seen["server-1"] | seen["server-2"] == set(ids), seen


def _fleet(api: httpx.Client, assets: Path) -> tuple[Tenant, Any, Any, Any]:
    """docs/operations.md steps 5 and 7: an organisation with its users, a base and a UAV bound to it, their
    asset files saved where the demo profile's daemons read them; and a UAV with a camera."""
    tenant = Tenant(api, ROOT_EMAIL, "stack")
    base = tenant.create_asset("landing_base", password=ASSET_PASSWORD)
    uav = tenant.create_asset(
        "uav", password=ASSET_PASSWORD, base_id=base["id"], attributes={"mass_g": 1450}
    )
    camera = tenant.create_asset(
        "uav",
        password=ASSET_PASSWORD,
        attributes={"camera": {"width": 320, "height": 240, "fps": 20}},
    )
    (assets / "base.abcf").write_bytes(base64.b64decode(base["config_file"]))
    (assets / "uav.abcf").write_bytes(base64.b64decode(uav["config_file"]))
    return tenant, base, uav, camera


def _reporting(
    api: httpx.Client, ops: dict[str, str], base: Any, uav: Any, after: datetime | None = None
) -> Any:
    """Both daemons' telemetry through the stack: the base's PLC up with the UAV on its scale,
    the UAV with a fix and a position, both sampled after `after` if given; returns the UAV's
    latest sample."""
    b = api.get(f"/api/v1/assets/{base['id']}/telemetry/latest", headers=ops)
    u = api.get(f"/api/v1/assets/{uav['id']}/telemetry/latest", headers=ops)
    if b.status_code != 200 or u.status_code != 200:
        return None
    bt, ut = b.json(), u.json()
    if after is not None and min(_when(bt["ts"]), _when(ut["ts"])) <= after:
        return None
    ok = (
        bt.get("plc_link") == "up"
        and bt.get("uav_present")
        and ut.get("gnss.fix") in ("3d", "dgps", "rtk_float", "rtk_fixed")
        and ut.get("position.lat") is not None
    )
    return ut if ok else None


async def _live_video(url: str, ops: dict[str, str], uav: Any, token: str) -> int:
    """A UAV on this host sends its camera as RTP where the server says (MEDIA_PUBLIC_IP and the
    Janus mountpoint's port, published by the compose file) until the server reports the stream
    live. Then, through the proxy, every read of the stream's state says live, and a viewer's
    WHEP exchange (an empty POST for Janus's offer, the answer PATCHed to its Location, DELETE)
    is answered, whichever replica each request would have reached. Returns the RTP port."""
    track = CameraTrack(pattern(320, 240), 320, 240, 20)
    publisher = RtpPublisher(url, uav["id"], lambda: token, track, recheck_s=2.0)
    sending = asyncio.create_task(publisher.run())
    viewer = JanusViewer(url, uav["id"], ops["Authorization"].removeprefix("Bearer "))
    try:
        async with httpx.AsyncClient(base_url=url, timeout=30) as api:

            async def state() -> str:
                r = await api.get(f"/api/v1/assets/{uav['id']}/video", headers=ops)
                assert r.status_code == 200, r.text
                return str(r.json()["state"])

            async def live() -> bool:
                return await state() == "live"

            await eventually(live, within=60, what="the UAV's RTP live in Janus", interval=0.5)
            assert [await state() for _ in range(6)] == ["live"] * 6
            offered = await viewer.start()  # asserts the PATCH's 204
            assert offered.status_code == 201, offered.text
        assert publisher.target is not None
        return publisher.target[1]
    finally:
        await viewer.close()
        sending.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await sending
        await track.aclose()  # type: ignore[attr-defined]


def _track_points(label: str | None) -> int:
    m = re.search(r": (\d+) track points", label or "")
    return int(m.group(1)) if m else -1


async def _console_follows(url: str, tenant: Tenant, base: Any, uav: Any, run_id: str) -> None:
    """The console, served by a replica's container through nginx, in Debian's Chromium: a viewer
    signs in; the base's and UAV's cards show their live state; the UAV's track grows as its
    telemetry arrives over the page's WebSocket through the proxy; the run's page reaches
    `completed` without a reload. No script error, nothing fetched from another origin."""
    from playwright.async_api import expect

    browsers = launch()
    browser = await anext(browsers)
    try:
        page, traffic = await open_page(browser, url + "/")
        await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
        uav_card = page.get_by_role("region", name=f"UAV {uav['name']}")
        base_card = page.get_by_role("region", name=f"Landing base {base['name']}")
        await expect(uav_card).to_contain_text("connected")
        await expect(uav_card).to_contain_text(re.compile(r"GNSS fix\s*(3d|dgps|rtk_\w+)"))
        await expect(base_card).to_contain_text(re.compile(r"PLC link\s*up"))
        await expect(page.locator("#link")).to_have_text("Live")  # the page's WebSocket is up
        track = uav_card.get_by_role("img", name=re.compile(f"^Live track of {uav['name']}"))
        first = _track_points(await track.get_attribute("aria-label"))

        async def grown() -> bool:
            return _track_points(await track.get_attribute("aria-label")) > max(first, 0) + 2

        await eventually(
            grown, within=60, what="the UAV's live track growing on the fleet page", interval=0.5
        )
        await shot(page, "stack-fleet")
        await page.goto(f"{url}/#/runs/{run_id}")
        detail = page.get_by_role("region", name=re.compile("^Run of"))
        ended = detail.get_by_text(re.compile("^(completed|aborted|failed)$")).first
        await expect(ended).to_be_visible(timeout=420_000)
        await shot(page, "stack-run")
        assert await ended.text_content() == "completed", await detail.inner_text()
        assert traffic.errors == [], traffic.errors
        assert traffic.off_origin(url) == [], traffic.off_origin(url)
    finally:
        await browsers.aclose()


def _published_udp(stack: Stack, service: str) -> set[int]:
    """The host's UDP ports that reach `service`'s container (`docker port`)."""
    out = run(["docker", "port", stack.container(service)], timeout=30).stdout
    return {int(m) for m in re.findall(r"^\d+/udp -> [^\n]*:(\d+)$", out, re.MULTILINE)}


def _when(ts: str) -> datetime:
    return datetime.fromisoformat(ts.replace("Z", "+00:00"))


def _ntrip_v1(port: int, mountpoint: str, email: str, password: str) -> bytes:
    """An NTRIP 1 rover on the proxy's caster port: the first bytes after `ICY 200 OK`."""
    creds = base64.b64encode(f"{email}:{password}".encode()).decode()
    request = (
        f"GET /{mountpoint} HTTP/1.0\r\nUser-Agent: NTRIP stack-test/1.0\r\n"
        f"Authorization: Basic {creds}\r\n\r\n"
    )
    with socket.create_connection(("127.0.0.1", port), timeout=20) as sock:
        sock.sendall(request.encode())
        got = b""
        while b"\r\n" not in got or len(got) < got.find(b"\r\n") + 64:
            chunk = sock.recv(4096)
            if not chunk:
                break
            got += chunk
    return got


def test_the_stack_starts_as_the_readme_says_and_flies_the_demo_through_the_proxy(site: Site):
    stack, url, assets = site.stack, site.url, site.assets
    try:
        wait_for(
            lambda: (
                stack.state("server-1", "Health.Status")
                == stack.state("server-2", "Health.Status")
                == "healthy"
            ),
            within=180,
            what="both replicas healthy",
            interval=1,
        )
        assert stack.state("migrate", "ExitCode") == "0"
        user = run(["docker", "exec", stack.container("server-1"), "id", "-un"], timeout=30)
        assert user.stdout.strip() == "aerobase"  # the image's unprivileged user

        # step 4: the first user, with the password in the environment (no terminal here)
        stack.compose(
            "run", "--rm", "-T", "-e", f"AEROBASE_PASSWORD={SUPERUSER_PASSWORD}",
            "migrate", "admin", "create-superuser", "--email", ROOT_EMAIL,
        )  # fmt: skip
        with httpx.Client(base_url=url, timeout=30) as api:
            _replicas_answer(stack, api)
            tenant, base, uav, camera = _fleet(api, assets)
            ops = tenant.h("admin")

            # live video: a UAV's RTP reaches Janus in its container on a published port, and viewers
            # are brokered through the proxy
            cfg = decrypt_config(base64.b64decode(camera["config_file"]), ASSET_PASSWORD)
            r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
            assert r.status_code == 200, r.text
            port = asyncio.run(_live_video(url, ops, camera, r.json()["access_token"]))
            assert port in _published_udp(stack, "janus"), port

            # step 7: the demo profile's world and daemons connect through the proxy
            stack.compose("--profile", "demo", "up", "-d", "--no-build", timeout=600)
            sample = wait_for(
                lambda: _reporting(api, ops, base, uav), within=180, what="both daemons reporting"
            )
            lat, lon = float(sample["position.lat"]), float(sample["position.lon"])
            r = api.patch(
                f"/api/v1/assets/{base['id']}",
                json={"attributes": {"latitude": lat, "longitude": lon}},
                headers=ops,
            )
            assert r.status_code == 200, r.text
            mission = _post(
                api,
                "/api/v1/missions",
                ops,
                {"name": "pad square", "items": mission_items(lat, lon)},
            )
            ids = {"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]}
            run_id = _post(api, "/api/v1/runs", ops, ids)["id"]

            # step 6: a rover on the proxy's caster port gets the base's RTCM3 while the run goes on
            got = _ntrip_v1(site.ntrip_port, base["name"], tenant.emails["viewer"], Tenant.PASSWORD)
            assert got.startswith(b"ICY 200 OK\r\n"), got[:80]
            assert got[len(b"ICY 200 OK\r\n")] == RTCM3_PREAMBLE, got[:80]

            # the console follows the run in a browser through the proxy until it completes
            asyncio.run(_console_follows(url, tenant, base, uav, run_id))

            def final() -> Any:
                body = api.get(f"/api/v1/runs/{run_id}", headers=ops).json()
                return (
                    body
                    if body["state"] in ("completed", "incomplete", "aborted", "failed")
                    else None
                )

            done = wait_for(final, within=420, what="the run to end", interval=1)
            assert done["state"] == "completed", done

            # step 8: a replica stopped is a graceful stop; the other goes on serving
            # docker sends SIGTERM and SIGKILLs after 10 s (exit code 137): exit code 0 means the
            # replica closed its sockets, handed back its leases and exited by itself within 10 s
            stack.compose("stop", "-t", "10", "server-1", timeout=60)
            stopped_at = datetime.now(UTC)
            exit_code = stack.state("server-1", "ExitCode")
            assert exit_code == "0", stack.compose("logs", "server-1").stdout[-3000:]
            for _ in range(4):
                assert api.get("/api/ready").status_code == 200
            wait_for(
                lambda: _reporting(api, ops, base, uav, after=stopped_at),
                within=90,
                what="both daemons' telemetry again, through server-2",
                interval=0.5,
            )
    except BaseException:
        print(stack.logs())
        raise
