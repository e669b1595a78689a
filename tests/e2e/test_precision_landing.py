"""Precision landing end to end: the world's camera and IR sensor, the agent's landing loop and the
simulated autopilot consuming LANDING_TARGET land the UAV on the charging contacts in real wind."""

from __future__ import annotations

import asyncio
import itertools
import socket
import time
from dataclasses import replace

import pytest

from asset_agent.autopilot.params import read_param
from asset_agent.precland.config import RetryConfig
from sim.vehicle.habits import profile
from tests.conftest import Tenant
from tests.e2e.harness import FINAL, platform
from tests.polling import eventually

pytestmark = [
    pytest.mark.slow,  # whole processes end to end: not in the fast lane
    pytest.mark.realtime,  # landing loops through the camera: ahead of the others (tests/priority.py)
]

# slow enough for the detector to see the descent frame by frame, and for the agent's latency in
# world seconds (its wall latency times SPEED) to stay small on a loaded machine: at 4x, with two
# evaluations running beside it, the windy landing came down 1-10 cm off, and 57 and 165 cm once
# each in ~15 runs without the descent gate (below); at 2x it takes ~100 s
SPEED = 2.0
GATE_M = 0.03  # an operator's tighter PLND_XY_DIST_MAX than the default 5 cm (see the windy test)
SEED = 21
# the autopilot as ArduPilot 4.x lands with LANDING_TARGET (its PLND), without the boot wait
PLND = replace(profile("ardupilot-4"), streams_at_boot="all", boot_s=0.0)


async def autopilot_params(p) -> dict[str, float]:
    """Every parameter of the simulated autopilot as it answers the agent's PARAM_REQUEST_READ."""
    return {n: await read_param(p.agent.autopilot, n) for n in list(p.copter.fence.params)}


async def watch_while_flying(p, flown: list[float]) -> None:
    """PLND_XY_DIST_MAX as the autopilot holds it, each step it flies."""
    while True:
        if p.copter.flying:
            flown.append(p.copter.param("PLND_XY_DIST_MAX"))
        await asyncio.sleep(0.01)


async def test_a_windy_run_lands_on_the_contacts_by_landing_target(
    live_server, tenant: Tenant, tmp_path
):
    async with platform(
        live_server.url,
        tenant,
        tmp_path,
        speed=SPEED,
        seed=SEED,
        precland={"autopilot": {"xy_dist_max_m": GATE_M}},
        habits=PLND,
    ) as p:
        # steady 5 m/s gusting 2.5, the evaluation's fused-wind5. The daemon sets the autopilot's
        # PLND_XY_DIST_MAX to GATE_M while it lands ([precland.autopilot]): its LAND descends
        # only that close to the pad (at 2x under load: 2.0-2.8 cm in 3 runs at 3 cm; at the
        # default 5 cm 4.1-5.3 in 5, at the radius' edge: the agent's latency moves the target).
        # At 6 m/s gusting 8 this path misses the 5 cm contacts in a fraction of runs, before
        # issue 19's agent changes too (bd8e607: 2 of 8 runs, 6.0 and 6.9 cm; e8e5557: 5 of 8,
        # 5.5-7.5 cm; at 4x): sampled through such a run, the autopilot's PLND estimate of the
        # pad stays within ~4 cm while the gusts swing the vehicle 5-9 cm around it under LAND —
        # ArduPilot's position hold, not the agent's estimate, sets that error; the gate (at 5
        # and at 3 cm) did not bring it within 5 cm there (3.8-8.0 cm in 4 runs, 1.9-10.1 in 3)
        p.world.weather.force(wind_mps=5.0, gust_mps=2.5)
        copter = p.copter
        lander = p.agent.lander
        assert lander is not None
        # a fault injected at run time through the server: IR readings dropped at random (the marker
        # still sees the pad); an unknown source is refused
        assert (await _command(p, "precland_fault", {"source": "ir", "r_drop": 0.3}))[
            "status"
        ] == "succeeded"
        assert (await _command(p, "precland_fault", {"source": "sonar"}))["status"] == "rejected"
        assert lander.faults["ir"].r_drop == 0.3
        # every parameter over MAVLink before the flight, and PLND_XY_DIST_MAX while it flies
        before = await autopilot_params(p)
        flown: list[float] = []
        watch = asyncio.create_task(watch_while_flying(p, flown))
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying",), 60)
        await eventually(
            lambda: (p.agent.autopilot.state.alt_rel or 0) > 10, 60, "the UAV to climb out"
        )
        # multipath: a 40 cm GNSS error that RTK does not remove; on GNSS alone the UAV would land
        # on the scale but beside the contacts
        copter.gnss.bias_ne_m = (0.3, -0.27)
        await p.wait_state(run_id, ("landing",), 90)
        body = await p.wait_state(run_id, FINAL, 180)
        error_m = copter.pad_distance()  # ground truth
        seen = (
            f"landing error {error_m * 100:.1f} cm, {lander.stats}, rate {lander.stats.target_rate_hz}"
            f" Hz, accepted by the autopilot {copter.plnd.accepted}"
        )
        print(f"precland e2e: {seen}")
        assert error_m < 0.05, seen
        assert body["state"] == "completed", (body["reason"], body["timeline"], seen)
        assert not body["alert"], (body["reason"], seen)  # charging started: contacts seated
        assert p.world.base.contacts_seated
        # the run report shows the touchdown offset the agent measured (issue 14 item 15: it was
        # always null) beside the base's confirmation, and the measurement matches the truth
        report = await _report(p, run_id)
        landing = report["landing"]
        print(f"precland e2e report: landing {landing}, truth {error_m:.3f} m")
        assert report["landing_error_m"] == landing["agent_offset_m"], report
        assert abs(landing["agent_offset_m"] - error_m) < 0.05, (landing, error_m)
        assert landing["agent_fix_sources"] and landing["agent_fix_age_s"] < 5, landing
        assert landing["agent_landing_path"] == "precision", landing
        assert landing["base_confirmed"] and landing["base_mass_g"] > 0, landing
        # the autopilot steered its descent with the agent's LANDING_TARGETs (its PLND took them),
        # descending only within the radius the daemon set: GATE_M, or ArduPilot's default once
        # the landing has lasted relax_after_s, held by gusts it could not beat (once on a loaded
        # machine: 181 s of targets, relaxed, landed 3.2 cm off). Near that age, either.
        gate = lander.config.autopilot
        lasted = lander.stats.last_sent_t - lander.stats.first_sent_t
        radii = {gate.xy_dist_max_at(lasted - 2.0), gate.xy_dist_max_at(lasted + 2.0)}
        assert GATE_M == gate.xy_dist_max_at(0.0)
        watch.cancel()
        held = flown[-1]  # to the touchdown
        assert any(held == pytest.approx(r) for r in radii), (held, lasted, radii, seen)
        # and given back once landed (precland/restore.py): every parameter as before the flight
        default = before["PLND_XY_DIST_MAX"]
        await eventually(lambda: copter.param("PLND_XY_DIST_MAX") == default, 30, "it back")
        assert await autopilot_params(p) == before
        assert lander.stats.landings >= 1 and lander.stats.targets_sent > 20, seen
        assert copter.plnd.was_acquired, seen
        assert copter.plnd.accepted > 20 and copter.plnd.rejected == 0, seen
        # The sending rate (20 Hz configured, >= 10 Hz enforced by the config; printed above) is a
        # figure of this machine's load, not of the code: the world runs 10x faster than the wall
        # clock, so a busy machine measured 2.3-6.5 Hz of world time in four runs while the
        # landings above still held. What the autopilot did with the targets is asserted instead.
        assert lander.stats.target_rate_hz is not None, seen


async def test_the_autopilots_own_precision_landing_fed_our_detections_lands_on_the_pad(
    live_server, tenant: Tenant, tmp_path
):
    """Issue 19 item 5: the simulated autopilot with ArduPilot's PLND (companion backend, its
    estimator, descent and retry rules: sim/vehicle/plnd.py), the agent sending each detection
    unfiltered (steering "autopilot"); the autopilot's LAND lands within 10 cm of the pad."""
    async with platform(
        live_server.url,
        tenant,
        tmp_path,
        speed=SPEED,
        seed=SEED,
        habits=PLND,
        precland={"steering": "autopilot"},
    ) as p:
        copter, lander = p.copter, p.agent.lander
        assert lander is not None and copter.plnd is not None
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying",), 60)
        await eventually(
            lambda: (p.agent.autopilot.state.alt_rel or 0) > 10, 60, "the UAV to climb out"
        )
        copter.gnss.bias_ne_m = (0.3, -0.27)  # 40 cm of multipath: GNSS alone lands beside
        await p.wait_state(run_id, ("landing",), 90)
        body = await p.wait_state(run_id, FINAL, 180)
        error_m = copter.pad_distance()  # ground truth
        seen = (
            f"landing error {error_m * 100:.1f} cm, {lander.stats}, accepted by the autopilot "
            f"{copter.plnd.accepted}, its estimator {copter.plnd.state}"
        )
        print(f"precland e2e (autopilot steering): {seen}")
        assert error_m < 0.10, seen
        assert body["state"] == "completed", (body["reason"], body["timeline"], seen)
        # the autopilot's estimator took the detections and steered: it found and kept the target
        assert copter.plnd.was_acquired and copter.plnd.accepted > 20, seen
        assert copter.plnd.rejected == 0, seen


async def test_a_pad_lost_below_3_m_on_a_plain_fix_is_abandoned_not_landed_blind(
    live_server, tenant: Tenant, tmp_path
):
    """Issue 19's hard case on the GNSS it was written against: every precision source fails
    below 3 m (injected through the server) and the base's corrections stop reaching the UAV (a
    plain 3D fix: its position drifts decimetres in the seconds of a blind descent). The UAV is
    not landed blind: the daemon takes it from the autopilot's LAND at the loss, retries, then
    climbs to its safe height and holds; the run fails at once with an alert, the base open."""
    async with platform(
        live_server.url, tenant, tmp_path, speed=SPEED, seed=SEED, habits=PLND, precland={}
    ) as p:
        copter, lander = p.copter, p.agent.lander
        assert lander is not None
        for source in ("marker", "ir"):
            done = await _command(p, "precland_fault", {"source": source, "below_m": 3.0})
            assert done["status"] == "succeeded", done
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying",), 60)
        copter.gnss.correction = lambda now, valid: None  # the RTCM never arrives: a plain fix
        await eventually(lambda: p.agent.autopilot.state.fix_type == 3, 30, "a plain 3D fix")
        await p.wait_state(run_id, ("landing",), 90)
        body = await p.wait_state(run_id, FINAL, 240)
        seen = f"{lander.stats}, losses {lander.takeover and lander.takeover.losses}"
        assert body["state"] == "failed" and body["cause"] == "landing_aborted", (
            body["reason"],
            body["timeline"],
            seen,
        )
        assert body["alert"] and "land it by hand" in body["reason"]
        # taken from LAND at the loss, its retries flown (climbing back into view above 3 m,
        # LAND again), then abandoned at the safe height
        took = lander.takeover
        assert took is not None and took.loss_guard is not None and took.losses, seen
        assert took.loss_guard.sequence.attempts == RetryConfig().max_attempts, seen
        assert copter.armed and copter.dyn.state.altitude > 10, seen
        assert p.world.base.pad_mass_g == 0 and p.world.base.can_vehicle_leave()


async def test_unreachable_sensors_leave_the_landing_to_gnss(live_server, tenant: Tenant, tmp_path):
    """Precision landing configured, camera and IR not there: nothing is sent, the UAV lands on RTK GNSS."""
    dead = {
        "camera_port": _closed_port(socket.SOCK_STREAM),
        "ir_port": _closed_port(socket.SOCK_DGRAM),
    }
    async with platform(live_server.url, tenant, tmp_path, precland=dead) as p:
        copter = p.copter
        run_id = await p.start_run()
        body = await p.wait_state(run_id, FINAL, 120)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert p.agent.lander is not None and p.agent.lander.stats.targets_sent == 0
        assert copter.precland.accepted == 0
        # nothing measured the touchdown: the report says so (null), the base still confirms
        report = await _report(p, run_id)
        assert report["landing_error_m"] is None and report["landing"]["agent_offset_m"] is None
        assert report["landing"]["base_confirmed"] and report["landing"]["landed_at"], report


async def test_a_camera_whose_timestamps_restart_mid_descent_lands_on_the_new_epoch(
    live_server, tenant: Tenant, tmp_path
):
    """The camera alone steers (no IR); below 7 m its timestamps start again from 0 (it rebooted,
    or the world restarted under the agent): the landing carries on with the new epoch's frames
    and lands on the contacts. Before issue 46 every frame after the restart looked a minute old
    to the agent: none was fused and no LANDING_TARGET went out for the rest of the descent."""
    async with platform(
        live_server.url, tenant, tmp_path, speed=SPEED, seed=SEED, precland={"ir_port": None}
    ) as p:
        lander, copter = p.agent.lander, p.copter
        assert lander is not None
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying",), 60)
        await eventually(
            lambda: (
                lander.loop is not None
                and lander.stats.targets_sent > 10
                and (p.agent.autopilot.state.alt_rel or 99.0) < 7.0
            ),
            240,
            "the camera to steer the descent",
        )
        sent, height = lander.stats.targets_sent, p.agent.autopilot.state.alt_rel
        measured = lander.stats.measured
        p.world.restart_sensor_clocks(0.0, parts=("camera",))
        await eventually(lambda: not copter.armed, 120, "the landing")
        body = await p.wait_state(run_id, FINAL, 120)
        events = await p.uav_events()
        landed = next(e for e in reversed(events) if e["name"] == "landed")
        seen = {
            "restarted_at_m": height,
            "targets_before": sent,
            "targets_after": lander.stats.targets_sent - sent,
            "measured_after": lander.stats.measured - measured,
            "epochs": lander.clock.epochs,
            "pad_distance_m": round(copter.pad_distance(), 4),
            "landed": landed["data"],
        }
        print(f"camera restart mid-descent: {seen}")
        # it steered on with the new epoch's frames: measured, not a target held from before
        assert lander.stats.measured - measured > 20, seen
        assert lander.stats.targets_sent - sent > 20, seen
        assert lander.clock.epochs == 1, seen
        # the camera alone may not see the pad at the loop's start (10 m): searched, then precision
        assert landed["data"]["landing_path"] in ("precision", "search-then-precision"), seen
        assert landed["data"]["fix_age_s"] < 1.0, seen  # measured to the end, not held from before
        assert not {"precland_silent", "landed_without_precision"} & {e["name"] for e in events}
        assert copter.pad_distance() < 0.05, seen
        assert body["state"] == "completed" and not body["alert"], (body["reason"], seen)


async def _report(p, run_id: str) -> dict:  # type: ignore[no-untyped-def]
    r = await p.api.get(f"/api/v1/runs/{run_id}/report", headers=p.tenant.h("viewer"))
    assert r.status_code == 200, r.text
    return dict(r.json())


def _closed_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _command(p, name: str, params: dict, limit_s: float = 20) -> dict:  # type: ignore[no-untyped-def]
    r = await p.api.post(
        f"/api/v1/assets/{p.ids['uav_id']}/commands",
        headers=p.tenant.h("operator"),
        json={"name": name, "params": params, "timeout_s": limit_s},
    )
    assert r.status_code == 202, r.text
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        body = (
            await p.api.get(f"/api/v1/commands/{r.json()['id']}", headers=p.tenant.h("viewer"))
        ).json()
        if body["status"] in ("succeeded", "rejected", "failed", "canceled", "timed_out"):
            return dict(body)
        await asyncio.sleep(0.05)
    raise AssertionError(f"{name} did not finish: {body}")


def test_the_sensor_clock_follows_the_capture_stamps_rate_and_offset():
    """Stamps from a clock running 4x with 100 s offset and jittery delivery: followed, never backwards."""
    from asset_agent.precland.clock import SensorClock

    wall = [0.0]
    clock = SensorClock(wall=lambda: wall[0])
    assert not clock.ready
    seen = []
    for i in range(200):
        wall[0] = i * 0.01
        delay = 0.002 * (i % 3)  # delivered 0-4 ms (wall) after capture
        clock.observe(100.0 + 4.0 * (wall[0] - delay))
        seen.append(clock.now())
    assert clock.ready and abs(clock.rate - 4.0) < 0.05
    assert abs(clock.now() - (100.0 + 4.0 * wall[0])) < 0.02
    assert all(b >= a for a, b in itertools.pairwise(seen))
