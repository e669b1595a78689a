"""RTK corrections in tests: a base daemon's reader on the simulated reference receiver, RTKLIB's
str2str as a third-party NTRIP client, and the frames a client wrote."""

from __future__ import annotations

import asyncio
import shutil
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from assetlink.link import Link
from assetlink.rtk import RtkConfig, RtkReader
from protocol.rtcm import Reframer
from sim.clock import SimClock
from sim.gnss.receiver import GnssReceiver, running_receiver


@asynccontextmanager
async def base_sending(link: Link) -> AsyncIterator[GnssReceiver]:
    """The simulated reference receiver (5x), read by the base daemon's RtkReader, its frames sent
    on the base's `link` as `rtcm` messages."""
    async with running_receiver(clock=SimClock(5.0)) as receiver:
        reader = RtkReader(
            RtkConfig(source=f"tcp://127.0.0.1:{receiver.port}"), on_frame=link.send_rtcm
        )
        reader.start()
        try:
            yield receiver
        finally:
            await reader.stop()


async def str2str(url: str, out: Path, *options: str) -> asyncio.subprocess.Process:
    """RTKLIB's str2str (Debian's rtklib) pulling `url` (ntrip://user:password@host:port/mount)
    into the file `out`; stop it with `stop`."""
    assert shutil.which("str2str"), "RTKLIB's str2str is missing: run .ci/install-system.sh"
    return await asyncio.create_subprocess_exec(
        "str2str", "-in", url, "-out", f"file://{out}", *options,
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
    )  # fmt: skip


async def stop(proc: asyncio.subprocess.Process) -> None:
    if proc.returncode is None:
        proc.terminate()
    await proc.wait()


def frames_in(path: Path) -> list[bytes]:
    """The CRC-valid RTCM3 frames in a file (none while it does not exist)."""
    return list(Reframer().feed(path.read_bytes())) if path.exists() else []
