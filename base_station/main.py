"""`aerobase base-station --config base.toml`: the landing-base daemon (setup / run / main).

The server link plugs in at ONE place: `run(app, link=...)`. A link is any
`async def link(station: Station, config: StationConfig) -> None` that forwards
`station.execute(name, params)` results and `station.subscribe()` events (plus
`station.telemetry()` at `config.telemetry_hz`) to the server; `server_link()` below is
where protocol/link.py gets wired (it returns None until then).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass

from assetlink.statefile import StateFileError
from asynckit.tasks import cancel_and_wait
from base_station.config import StationConfig, load_config
from base_station.coordinator import Coordinator
from base_station.station import Station

log = logging.getLogger(__name__)

LinkRunner = Callable[[Station, StationConfig], Awaitable[None]]


@dataclass
class App:
    """The daemon's parts, built by `setup` and driven by `run`."""

    config: StationConfig
    coordinator: Coordinator
    station: Station


def setup(config: StationConfig) -> App:
    """Build the daemon (no I/O yet)."""
    coordinator = Coordinator(config)
    return App(config, coordinator, Station(coordinator, config))


def server_link(config: StationConfig) -> LinkRunner | None:
    """THE place where the server link (protocol/link.py) is wired; None without an asset file.

    Raises ConfigFileError / PasswordSourceError (one-line messages) when the file cannot be read.
    """
    if not config.server.config_file:
        log.warning("no [server] config_file: running without a server link")
        return None
    from pathlib import Path

    from assetlink.configfile_cli import load_config as load_asset
    from base_station.server_link import link_runner, make_link

    asset = load_asset(
        Path(config.server.config_file).expanduser(), config.server.password_file or None
    )
    if asset.kind != "landing_base":
        raise ValueError(
            f"{config.server.config_file} is a {asset.kind}'s file, not a landing base's"
        )
    state = Path(config.server.state_file).expanduser()
    return link_runner(make_link(asset, state, config.server.url or None))


async def run(app: App, stop: asyncio.Event | None = None, link: LinkRunner | None = None) -> None:
    """Run until `stop` is set: poll the PLC, feed its watchdog, serve the link if any.

    Starting never writes a motion coil: the daemon reads the PLC's state and carries on (and
    clears a watchdog latch its own absence left, see coordinator.py). The server link starts
    once the PLC has been read (or could not be), so a command replayed at once is judged
    against the base as it is, not against "not connected yet".
    """
    stop = stop or asyncio.Event()
    await app.coordinator.start()
    plc = app.config.plc
    await app.coordinator.wait_next(0, 2 * plc.timeout_s + 1.0)
    link_task = asyncio.ensure_future(link(app.station, app.config)) if link else None
    try:
        await stop.wait()
    finally:
        await cancel_and_wait([link_task])  # logs what the link ended with
        await app.station.shutdown()
        await app.coordinator.stop()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase base-station`."""
    ap = argparse.ArgumentParser(prog="aerobase base-station", description=__doc__.splitlines()[0])
    ap.add_argument("--config", required=True, help="TOML configuration file")
    ap.add_argument("--log-level", default="INFO")
    args = ap.parse_args(argv)
    logging.basicConfig(
        level=args.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s %(message)s"
    )
    logging.getLogger("httpx").setLevel(logging.WARNING)  # else a line per login and refresh
    try:
        config = load_config(args.config)
    except (OSError, ValueError) as err:
        log.error("cannot load configuration %s: %s", args.config, err)
        return 2
    from assetlink.configfile import ConfigFileError
    from assetlink.configfile_cli import PasswordSourceError

    try:
        link = server_link(config)
    except (OSError, ValueError, ConfigFileError, PasswordSourceError) as err:
        log.error("cannot open the asset configuration file: %s", err)
        return 1
    app = setup(config)

    async def _main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError):
                loop.add_signal_handler(sig, stop.set)
        await run(app, stop, link)

    try:
        asyncio.run(_main())
    except StateFileError as err:
        log.error("%s", err)
        return 1
    return 0
