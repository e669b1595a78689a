"""`aerobase.ports.free_port`: a port for a program started later, picked where no outgoing
connection can take it first (below the kernel's ephemeral range)."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from aerobase import ports


def test_a_picked_port_is_below_the_ephemeral_range_and_free_for_tcp_and_udp():
    low = ports.ephemeral_low()
    picked = {ports.free_port() for _ in range(20)}
    assert all(ports.PICK_FROM <= p < low for p in picked)
    assert len(picked) > 10  # at random: parallel workers do not pick alike
    port = picked.pop()
    for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", port))


def test_a_port_in_use_is_not_picked(monkeypatch: pytest.MonkeyPatch):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        assert not ports.port_free(port)
        assert ports.port_free(port, socket.SOCK_DGRAM)  # only TCP is taken
        real, forced = ports._pick.randrange, [port, port]  # picked twice, then at random
        monkeypatch.setattr(
            ports._pick, "randrange", lambda a, b: forced.pop() if forced else real(a, b)
        )
        monkeypatch.setattr(ports, "PICK_FROM", 1024)
        monkeypatch.setattr(ports, "ephemeral_low", lambda: 65535)
        assert ports.free_port() != port
        assert not forced


def test_with_no_room_below_the_range_the_kernel_picks(tmp_path: Path, monkeypatch):
    kernels = ports.ephemeral_low()  # where bind(0) picks on this machine
    range_file = tmp_path / "ip_local_port_range"
    range_file.write_text("15500\t60999\n")
    monkeypatch.setattr(ports, "RANGE_FILE", range_file)
    assert ports.ephemeral_low() == 15500
    assert ports.free_port() >= min(kernels, 15500)  # bind(0)'s, not one picked below 15500
    range_file.write_text("garbage")
    assert ports.ephemeral_low() == 32768
