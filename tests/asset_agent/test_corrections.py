"""RTK corrections into the autopilot from two paths: the base's local stream first, the server's
relay while it is silent, never the same frame twice (issue 46)."""

from __future__ import annotations

from asset_agent.corrections import Corrections
from protocol.rtcm import build_frame


def frame(n: int) -> bytes:
    """A distinct MSM-like frame per epoch n."""
    return build_frame(bytes([0x43, 0x70]) + n.to_bytes(4, "big") + bytes(20))


def test_the_local_stream_wins_the_server_fills_its_silence_and_nothing_goes_twice() -> None:
    wall = [0.0]
    injected: list[bytes] = []
    c = Corrections(injected.append, local_silence_s=3.0, wall=lambda: wall[0])
    # both paths deliver epochs 0-9, the server's copy 0.3 s behind: the local one is injected
    for n in range(10):
        c.from_local(frame(n))
        wall[0] += 0.3
        c.from_server(frame(n))
        wall[0] += 0.7
    assert injected == [frame(n) for n in range(10)]
    assert c.skipped == 10 and c.using == "local"
    # the local stream falls silent (the base's network cut): within 3 s the server's relay
    # takes over; until then its frames are dropped as the local path is presumed alive
    for n in range(10, 20):
        c.from_server(frame(n))
        wall[0] += 1.0
    assert c.using == "server"
    taken = injected[10:]
    assert taken == [frame(n) for n in range(12, 20)], [f[5:9] for f in taken]
    # the local stream comes back with a frame the server already delivered: not injected again
    c.from_local(frame(19))
    assert c.duplicates == 1 and injected[-1] == frame(19) and len(injected) == 18
    c.from_local(frame(20))
    c.from_server(frame(20))
    assert injected[-1] == frame(20) and len(injected) == 19 and c.using == "local"


def test_without_a_local_stream_every_server_frame_is_injected_repeats_included() -> None:
    """A site without the local path: the server's relay as before, and a frame that repeats
    (a station description sent again, byte for byte) still reaches the autopilot each time."""
    wall = [0.0]
    injected: list[bytes] = []
    c = Corrections(injected.append, wall=lambda: wall[0])
    station = build_frame(bytes([0x3E, 0xD0]) + bytes(17))  # type 1005, identical every time
    for n in range(5):
        c.from_server(station)
        c.from_server(frame(n))
        wall[0] += 1.0
    assert len(injected) == 10 and c.duplicates == 0
