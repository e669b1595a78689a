"""Recording: each publication's frames land on disk as WebM segments, never re-encoded."""

from __future__ import annotations

import base64
import io
import itertools
import json
import os
import time
import uuid
from collections.abc import Iterator
from datetime import datetime, timedelta
from pathlib import Path

import av
import httpx
import pytest
from sqlalchemy import update

from server.video.recording import apply_retention, vp8_size
from tests.conftest import LiveServer, Tenant, test_settings
from tests.polling import eventually
from tests.video.peers import publisher
from tests.video.test_video_api import uav_with_camera


@pytest.fixture(scope="module")
def recording_server(
    database_url: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("recordings")
    server = LiveServer(
        test_settings(
            database_url,
            video_ice_loopback=True,
            video_record_dir=folder,
            video_record_segment_s=2.0,
        )
    ).start()
    yield server
    server.stop()


@pytest.mark.slow
async def test_a_publication_is_recorded_in_segments_with_frame_times(
    recording_server: LiveServer, superuser_email: str
):
    with httpx.Client(base_url=recording_server.url, timeout=30) as api:
        tenant = Tenant(api, superuser_email, label="rec")
        asset_id, asset_token = uav_with_camera(tenant, api)
        other = Tenant(api, superuser_email, label="rec-other")
    pub = publisher(recording_server.url, asset_id, asset_token, 320, 240, 20)
    h = tenant.h("viewer")
    base = f"/api/v1/assets/{asset_id}/video/recordings"
    async with httpx.AsyncClient(base_url=recording_server.url, timeout=30) as c:
        await pub.publish_once()
        t0 = time.time()

        async def two_segments() -> bool:
            return len((await c.get(base, headers=h)).json()) >= 3

        # a segment is cut every 2 s at a keyframe the recorder asks the publisher for (PLI)
        try:
            await eventually(two_segments, within=30, what="three segments")
        finally:
            await pub.stop()
            await pub.track.aclose()  # type: ignore[attr-defined]
        listed = (await c.get(base, headers=h)).json()
        assert listed[0]["started_at"] > listed[-1]["started_at"]  # newest first
        oldest = listed[-1]
        assert oldest["name"].endswith(".webm") and oldest["bytes"] > 0
        started = datetime.fromisoformat(oldest["started_at"].replace("Z", "+00:00"))
        assert abs(started.timestamp() - t0) < 10
        webm = await c.get(oldest["url"], headers=h)
        assert webm.status_code == 200 and webm.headers["content-type"] == "video/webm"
        times = (await c.get(oldest["times_url"], headers=h)).text.splitlines()
        # another organisation sees nothing; a crafted name is not a path
        assert (await c.get(base, headers=other.h("viewer"))).status_code == 404
        assert (await c.get(f"{base}/..%2F..%2Fetc%2Fpasswd", headers=h)).status_code == 404
        assert (await c.get(f"{base}/x.webm", headers=h)).status_code == 404
    container = av.open(io.BytesIO(webm.content))
    frames = [f for f in container.decode(video=0)]
    assert frames and {(f.width, f.height) for f in frames} == {(320, 240)}
    assert len(times) == len(frames)  # one time per frame, every frame decodable
    stamps = [json.loads(line) for line in times]
    assert all(b["pts"] > a["pts"] and b["t"] >= a["t"] for a, b in itertools.pairwise(stamps))
    # the times' pts are the documented 90 kHz: frame i plays at pts/90000 s in the WebM (ms)
    for frame, stamp in zip(frames, stamps, strict=True):
        assert abs(float(frame.time) - stamp["pts"] / 90000) <= 0.001, (frame.time, stamp)
    assert abs(stamps[0]["t"] / 1000 - t0) < 10


def test_retention_deletes_by_age_then_oldest_beyond_the_size(tmp_path: Path):
    folder = tmp_path / "asset"
    folder.mkdir()
    now = time.time()
    for i, age in enumerate((10 * 86400, 3600, 1800, 60)):
        seg = folder / f"2026010{i}T000000.000000Z.webm"
        seg.write_bytes(b"x" * 1000)
        seg.with_suffix(".times.jsonl").write_text("{}\n")
        os.utime(seg, (now - age, now - age))
    # the 10-day-old one goes by age; then the oldest until 2 segments (2000 bytes) remain
    assert apply_retention(tmp_path, max_age_s=7 * 86400, max_bytes=2000, now=now) == 2
    left = sorted(p.name for p in folder.glob("*.webm"))
    assert left == ["20260102T000000.000000Z.webm", "20260103T000000.000000Z.webm"]
    assert sorted(p.name for p in folder.glob("*.jsonl")) == [
        "20260102T000000.000000Z.times.jsonl",
        "20260103T000000.000000Z.times.jsonl",
    ]


def test_vp8_size_reads_keyframes_only():
    key = bytes.fromhex("3012009d012a4001f000")
    assert vp8_size(key) == (320, 240)
    assert vp8_size(b"\x31" + key[1:]) is None  # an interframe
    assert vp8_size(b"") is None


def _utc(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00"))


def _uav_at_base(tenant: Tenant, api: httpx.Client) -> tuple[dict[str, str], str]:
    """A base, a UAV with a camera housed there, a mission; the run's ids and the UAV's token."""
    from assetlink.configfile import decrypt_config

    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset(
        "uav", base_id=base["id"], attributes={"camera": {"width": 320, "height": 240}}
    )
    cfg = decrypt_config(base64.b64decode(uav["config_file"]), "asset-password-123")
    token = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    assert token.status_code == 200, token.text
    mission = api.post(
        "/api/v1/missions",
        headers=tenant.h("operator"),
        json={"name": "square", "items": [{"command": 22, "alt": 20}, {"command": 20}]},
    )
    assert mission.status_code == 201, mission.text
    ids = {"mission_id": mission.json()["id"], "uav_id": uav["id"], "base_id": base["id"]}
    return ids, token.json()["access_token"]


@pytest.mark.slow
async def test_the_run_report_lists_the_segments_recorded_during_the_flight(
    recording_server: LiveServer, database_url: str, superuser_email: str
):
    """A run's report lists the UAV's segments overlapping its flight, oldest first, with their
    download URLs. The run is real (started and aborted through the API); its flight window is
    written into its row, since flying it needs the simulated world (tests/e2e)."""
    from server.kit.db import make_engine
    from server.runs.models import Run

    with httpx.Client(base_url=recording_server.url, timeout=30) as api:
        tenant = Tenant(api, superuser_email, label="rec-run")
        ids, token = _uav_at_base(tenant, api)
    asset_id = ids["uav_id"]
    h = tenant.h("viewer")
    pub = publisher(recording_server.url, asset_id, token, 320, 240, 20)
    async with httpx.AsyncClient(base_url=recording_server.url, timeout=30) as c:
        base_url = f"/api/v1/assets/{asset_id}/video/recordings"
        await pub.publish_once()

        async def four_segments() -> bool:
            return len((await c.get(base_url, headers=h)).json()) >= 4

        try:
            await eventually(four_segments, within=40, what="four segments")
        finally:
            await pub.stop()
            await pub.track.aclose()  # type: ignore[attr-defined]
        segments = (await c.get(base_url, headers=h)).json()[::-1]  # oldest first
        for s in segments[:-1]:  # every segment but the newest is complete: a time span
            assert _utc(s["ended_at"]) >= _utc(s["started_at"]), s
        run = (await c.post("/api/v1/runs", headers=tenant.h("operator"), json=ids)).json()
        report_url = f"/api/v1/runs/{run['id']}/report"
        await c.post(f"/api/v1/runs/{run['id']}/abort", headers=tenant.h("operator"), json={})

        async def aborted() -> bool:
            r = await c.get(f"/api/v1/runs/{run['id']}", headers=h)
            return r.json()["state"] == "aborted"

        await eventually(aborted, within=20, what="the aborted run")
        report = (await c.get(report_url, headers=h)).json()
        assert report["recordings"] == []  # it never took off

        # a flight from just after the second segment began until just after the third began
        def at(text: str, plus_s: float) -> datetime:
            return _utc(text) + timedelta(seconds=plus_s)

        took_off, landed = at(segments[1]["started_at"], 0.1), at(segments[2]["started_at"], 0.1)
        engine = make_engine(database_url)
        async with engine.begin() as conn:
            await conn.execute(
                update(Run)
                .where(Run.id == uuid.UUID(run["id"]))
                .values(flight_started_at=took_off, flight_ended_at=landed)
            )
        await engine.dispose()
        r = await c.get(report_url, headers=h)
        assert r.status_code == 200, r.text
        listed = r.json()["recordings"]
        assert [s["name"] for s in listed] == [segments[1]["name"], segments[2]["name"]]
        assert listed[0] == segments[1]  # the same entry as the asset's list: URLs, times, size
        webm = await c.get(listed[0]["url"], headers=h)
        assert webm.status_code == 200 and webm.headers["content-type"] == "video/webm"
