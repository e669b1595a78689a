"""Broker channel names are spelt in one module; everyone else calls its functions."""

from __future__ import annotations

import re
import uuid
from pathlib import Path

from server.realtime import channels

ROOT = Path(__file__).resolve().parents[2] / "server"
# a string literal that starts like a channel or presence key: "asset.{", f"cmd.{", "sessions.ended", ...
SPELT = re.compile(r"""f?["'](?:asset|cmd|rtcm|conn\.asset)\.\{|["']sessions\.ended["']""")


def test_channel_names() -> None:
    i = uuid.UUID(int=7)
    assert channels.asset_channel(i) == f"asset.{i}"
    assert channels.command_channel(i) == f"cmd.{i}"
    assert channels.rtcm_channel(i) == f"rtcm.{i}"
    assert channels.presence_key(i) == f"conn.asset.{i}"
    assert channels.sessions_ended_channel() == "sessions.ended"


def test_no_channel_name_is_spelt_outside_the_channels_module() -> None:
    offenders = [
        f"{path.relative_to(ROOT.parent)}:{n}"
        for path in ROOT.rglob("*.py")
        if path.name != "channels.py"
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if SPELT.search(line)
    ]
    assert offenders == []
