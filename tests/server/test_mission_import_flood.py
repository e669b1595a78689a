"""Issue 48 finding 5: oversized mission imports are refused without stalling the server.

Eight files just under the 5 MiB import limit, each holding about a hundred times the 1,000 items
a mission may have, are sent at once to an `aerobase server` process of its own (so that the
test's own work does not share the server's interpreter) while the health check is asked in a
loop. Each import is refused with a clean 422 naming the item limit (a plan's parse stops at the
first item over it), and the health check keeps answering; its slowest answer is measured and
printed (`-s`)."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import httpx
import pytest

from tests.conftest import Tenant
from tests.replicas import replicas

MIB = 1024 * 1024
IMPORTS = 8
# the health check's slowest answer while they arrive. What holds the server's event loop now is
# a few C calls of at most tens of milliseconds (decoding and splitting the body); on this 2-core
# machine at a load average of 12-15 the slowest answer was still 1.2-1.9 s (median 14-75 ms), the
# scheduler's doing, so the bound is loose; the early stop itself is asserted by what the refusal
# says ("more than 1000": the parse stopped there)
SLOWEST_HEALTH_S = 2.5


def _oversized_plan(limit: int = 5 * MIB - 64 * 1024) -> bytes:
    """A QGroundControl plan of tiny waypoints, as many as fit under `limit` bytes."""
    item = '{"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,0,47.39,8.54,20]}'
    count = (limit - 200) // (len(item) + 1)
    items = ",".join([item] * count)
    return (
        '{"fileType":"Plan","mission":{"plannedHomePosition":[47.39,8.54,400],'
        f'"items":[{items}]}}}}'
    ).encode()


def _oversized_wpl(limit: int = 5 * MIB - 64 * 1024) -> bytes:
    """A QGC WPL 110 file of waypoints, as many as fit under `limit` bytes."""
    lines = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t47.39\t8.54\t400\t1"]
    size = sum(len(ln) + 1 for ln in lines)
    while size < limit - 100:
        lines.append(f"{len(lines) - 1}\t0\t3\t16\t0\t0\t0\t0\t47.39\t8.54\t20\t1")
        size += len(lines[-1]) + 1
    return "\n".join(lines).encode()


async def test_eight_oversized_imports_are_refused_while_the_health_check_answers(
    database_url: str, tenant: Tenant, tmp_path: Path
):
    plan, wpl = _oversized_plan(), _oversized_wpl()
    assert len(plan) < 5 * MIB and len(wpl) < 5 * MIB
    assert json.loads(plan)["mission"]["items"][0]["command"] == 16
    headers = tenant.h("operator")
    with replicas(database_url, tmp_path, count=1) as [(port, _)]:
        url = f"http://127.0.0.1:{port}"
        async with (
            httpx.AsyncClient(base_url=url, timeout=120) as c,
            httpx.AsyncClient(base_url=url, timeout=30) as probe,
        ):
            assert (await probe.get("/api/health")).status_code == 200  # its connection is open
            latencies: list[float] = []
            done = asyncio.Event()

            async def health() -> None:
                while not done.is_set():
                    started = time.perf_counter()
                    r = await probe.get("/api/health")
                    latencies.append(time.perf_counter() - started)
                    assert r.status_code == 200, r.text
                    await asyncio.sleep(0.02)

            async def one(n: int) -> httpx.Response:
                body, kind = (plan, "application/json") if n % 2 else (wpl, "text/plain")
                return await c.post(
                    "/api/v1/missions/import",
                    content=body,
                    headers={**headers, "Content-Type": kind},
                )

            prober = asyncio.create_task(health())
            try:
                answers = await asyncio.gather(*(one(n) for n in range(IMPORTS)))
            finally:
                done.set()
                await prober
    for r in answers:
        assert r.status_code == 422, r.text[:300]
        error = r.json()["error"]
        assert error["code"] == "import_rejected"
        problems = error["details"]
        assert [p["what"] for p in problems] == ["too many items"], problems[:3]
        assert problems[0]["limit"] == 1000
        if r.request.headers["content-type"] == "application/json":  # counted while parsing
            assert problems[0]["value"] == "more than 1000", problems
        else:  # a waypoint file's lines are counted before any is read
            assert problems[0]["value"] == len(wpl.split(b"\n")) - 2
    slowest = max(latencies)
    print(
        f"\nhealth check during {IMPORTS} oversized imports: {len(latencies)} answers, "
        f"slowest {slowest * 1000:.0f} ms, median "
        f"{sorted(latencies)[len(latencies) // 2] * 1000:.0f} ms"
    )
    # answered while they arrived (how many times depends on how fast the imports are refused:
    # 4 answers in one CI run where all eight took under 130 ms)
    assert latencies, "the health check did not answer while the imports arrived"
    assert slowest <= SLOWEST_HEALTH_S, f"the health check took {slowest * 1000:.0f} ms"


@pytest.mark.parametrize("kind", ["application/json", "text/plain"])
def test_an_import_just_over_the_item_limit_is_refused_and_one_at_it_is_taken(
    api: httpx.Client, tenant: Tenant, kind: str
):
    """The early count is the same rule as the mission's own: 1,000 items are taken, 1,001 not."""
    for count, status in ((1000, 201), (1001, 422)):
        if kind == "text/plain":
            lines = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t47.39\t8.54\t400\t1"]
            lines += [f"{n + 1}\t0\t3\t16\t0\t0\t0\t0\t47.39\t8.54\t20\t1" for n in range(count)]
            body = "\n".join(lines).encode()
        else:
            item = {"type": "SimpleItem", "command": 16, "frame": 3}
            item["params"] = [0, 0, 0, 0, 47.39, 8.54, 20]
            doc = {"fileType": "Plan", "mission": {"plannedHomePosition": [47.39, 8.54, 400]}}
            doc["mission"]["items"] = [item] * count  # type: ignore[index]
            body = json.dumps(doc).encode()
        r = api.post(
            "/api/v1/missions/import",
            content=body,
            headers={**tenant.h("operator"), "Content-Type": kind},
        )
        assert r.status_code == status, r.text[:300]
        if status == 422:
            problems = r.json()["error"]["details"]
            assert [p["what"] for p in problems] == ["too many items"]
