"""`aerobase demo --once --autopilot URL --autopilot-watch URL2` against an autopilot the demo did
not start: our simulated one, served alone by `aerobase sim autopilot` as its own process on its
own two TCP ports, as ArduPilot SITL serves SERIAL0 and SERIAL1, with ArduPilot 4.x's habits (35 s
from boot to armable, only HEARTBEAT until streams are asked for on each port)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import free_port, reachable
from tests.polling import wait_for

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane

SPEED = "5"


@pytest.fixture
def external_autopilot(tmp_path):
    """The simulated autopilot as a separate process: (agent's URL, watcher's URL)."""
    port, port2 = free_port(), free_port()
    log = open(tmp_path / "autopilot.log", "wb")
    proc = subprocess.Popen(
        [
            *(sys.executable, "-m", "aerobase.cli", "sim", "autopilot", "--speed", SPEED),
            *("--tcp-port", str(port), "--tcp-port2", str(port2)),
            *("--udp-port", "0", "--control-port", "0", "--autopilot-profile", "ardupilot-4"),
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        wait_for(
            lambda: (
                proc.poll() is None
                and reachable("127.0.0.1", port)
                and reachable("127.0.0.1", port2)
            ),
            within=30,
            what="the simulated autopilot's two MAVLink ports",
        )
        yield f"tcp:127.0.0.1:{port}", f"tcp:127.0.0.1:{port2}"
    finally:
        proc.terminate()
        proc.wait(10)
        log.close()


def test_demo_flies_an_external_autopilot_with_precision_landing(tmp_path, external_autopilot):
    url, watch = external_autopilot
    r = subprocess.run(
        [
            *(sys.executable, "-m", "aerobase.cli", "demo", "--once", "--speed", SPEED),
            *("--autopilot", url, "--autopilot-watch", watch),
            *("--port", str(free_port()), "--dir", str(tmp_path / "demo")),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    for step in (
        "[1/8] Checking",
        "[2/8] Opening",
        "[3/8] Uploading",
        "[4/8] Flying",
        "[5/8] Returning",
        "[6/8] Confirming",
        "[7/8] Closing",
        "[8/8] Starting to charge",
        "Completed: charging; the run is over",
    ):
        assert step in out, (step, out)
    assert "around the autopilot at " + url in out
    timeline = next(line for line in out.splitlines() if "timeline:" in line)
    assert "flying (mission uploaded and verified)" in timeline, timeline
    assert "landing (mission finished)" in timeline, timeline
    assert "confirming (the UAV reports it has landed)" in timeline, timeline
    events = next(line for line in out.splitlines() if "UAV events:" in line)
    names = events.split("UAV events: ")[1].split(", ")
    assert names.index("took_off") < names.index("landed"), events
    world = (tmp_path / "demo" / "world.log").read_text()
    assert "the vehicle's home (the pad) is (41.178, -8.596, 120.0)" in world, world
    # precision landing flew it: LANDING_TARGET went to the autopilot and it landed seated
    agent = (tmp_path / "demo" / "agent.log").read_text()
    assert "precland: active" in agent and "LANDING_TARGET sent" in agent, agent
    follower = [line for line in world.splitlines() if "follower:" in line]
    assert "seated on the pad" in follower[-1], follower
