"""deploy/systemd/: the daemons' unit files, checked by systemd's own parser, run against this
checkout's `aerobase` as the units would run it, and held to what the daemons' restart behaviour
relies on (docs/operations.md, "The daemons as services")."""

from __future__ import annotations

import configparser
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.deploy.conftest import program

UNITS = Path(__file__).resolve().parents[2] / "deploy" / "systemd"
INSTALLED = "/opt/aerobase/.venv/bin/aerobase"  # where the units expect the project
HERE = str(Path(sys.executable).with_name("aerobase"))  # this checkout's, in its .venv
NAMES = ("aerobase-agent.service", "aerobase-base-station.service")


def _unit(name: str) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(interpolation=None, strict=False)
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # keys keep their case
    parser.read_string((UNITS / name).read_text())
    return parser


def test_every_unit_file_is_here() -> None:
    assert sorted(p.name for p in UNITS.glob("*.service")) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_systemd_reads_the_unit_without_a_complaint(name: str, tmp_path: Path) -> None:
    verify = program("systemd-analyze", "systemd")
    # as installed, but on this checkout's program (verify checks that ExecStart exists)
    text = (UNITS / name).read_text()
    assert INSTALLED in text
    (tmp_path / name).write_text(text.replace(INSTALLED, HERE))
    run = subprocess.run(
        [verify, "verify", str(tmp_path / name)], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0 and not (run.stdout + run.stderr).strip(), run.stdout + run.stderr


@pytest.mark.parametrize("name", NAMES)
def test_the_units_command_line_is_one_the_daemon_takes(name: str) -> None:
    argv = shlex.split(_unit(name)["Service"]["ExecStart"])
    assert argv[0] == INSTALLED
    run = subprocess.run([HERE, *argv[1:], "--help"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and "--config" in run.stdout, run.stderr


@pytest.mark.parametrize("name", NAMES)
def test_the_daemon_comes_back_however_often_it_stops(name: str) -> None:
    unit = _unit(name)
    assert unit["Service"]["Restart"] == "always"
    assert unit["Unit"]["StartLimitIntervalSec"] == "0"  # no give-up after a burst of restarts
    assert unit["Service"]["User"] == "aerobase"  # never root
    assert unit["Service"]["StateDirectory"] == "aerobase"  # its outbox: /var/lib/aerobase
