"""`aerobase demo --once`: every part as its own process, one scheduled survey run to completion."""

from __future__ import annotations

import subprocess
import sys

import pytest

from aerobase.ports import free_port

pytestmark = [
    pytest.mark.slow,  # whole processes end to end: not in the fast lane
    # above the demo's own 240 s timeout, so that one fails first, with the demo's output
    # (pytest's default 180 s cut it off; 104 and 136 s seen in full runs)
    pytest.mark.timeout(300),
]


# what the demo prints as the run walks its eight steps
DEMO_STEPS = (
    "[1/8] Checking",
    "[2/8] Opening",
    "[3/8] Uploading",
    "[4/8] Flying",
    "[5/8] Returning",
    "[6/8] Confirming",
    "[7/8] Closing",
    "[8/8] Starting to charge",
)


def test_demo_runs_a_scheduled_survey_to_completion(tmp_path):
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "aerobase.cli",
            "demo",
            "--once",
            "--port",
            str(free_port()),
            "--dir",
            str(tmp_path / "demo"),
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    for step in (*DEMO_STEPS, "Completed"):
        assert step in out, (step, out)
    assert out.count("[2/8] Opening") == 1  # each step once
    # the agent streams the simulated downward camera through the server (issue 15)
    assert "live video of uav-porto-1 (640x480 VP8" in out, out
    # the landing as the agent measured it, and the base's scale
    assert "cm from the pad's centre" in out and "the base weighed it" in out, out
    assert "stopping every process" in out
    # the agent publishes its camera once its link has a session, not before (a 401 and a retry)
    agent_log = (tmp_path / "demo" / "agent.log").read_text()
    assert "video publish failed" not in agent_log, agent_log
