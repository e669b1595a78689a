"""The simulated world: clock, weather, landing base (PLC on Modbus TCP) and pluggable parts.

`World` is an async context manager that starts everything on its configured ports (0 = ask
the OS) and exposes the bound ports in `world.ports`. One loop steps the physics in
SIMULATED time (`SimClock`, speed factor) and the PLC's communication timing in WALL time.

Extension points for the parts others write (vehicle, GNSS receiver, camera):

- `world.add_part(part)` before `start()`: a `WorldPart` gets `start(world)` / `stop()`,
  `step(dt_sim)` on every physics step, and may contribute an APIRouter to the control app;
- `world.base` (the `LandingBase`: `can_vehicle_leave()`, `set_pad_load(...)`,
  `pad_geodetic`), `world.weather.wind_ne(t_sim)`, `world.clock`, `world.config` (ports).

Command line: `aerobase sim world [--speed X] [--seed N] [--plc-port 5020] [--gnss-port 5021]
[--mavlink-port 5760] [--control-port 8090] [--host 127.0.0.1] [--follow URL]` (`--follow`: no
simulated vehicle; the world follows an external autopilot, see `sim.follow`).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from asynckit.tasks import cancel_and_wait
from sim.clock import SimClock
from sim.plc import BaseParams, LandingBase, PlcServer
from sim.power import PowerParams, PowerSystem
from sim.weather import Weather, WeatherParams

log = logging.getLogger(__name__)

STEP_WALL_S = 0.02
MAX_SUBSTEP_SIM_S = 0.5


class WorldPart(Protocol):
    """A simulated part plugged into the world (vehicle, GNSS receiver, camera, ...)."""

    name: str

    async def start(self, world: World) -> None:
        """Start serving (bind ports, start tasks); record bound ports in `world.ports`."""

    async def stop(self) -> None:
        """Stop serving and release every resource."""

    def step(self, dt_sim: float) -> None:
        """Advance the part's physics by `dt_sim` simulated seconds."""

    def routers(self) -> list[Any]:
        """FastAPI APIRouters to mount on the control interface (may be empty)."""


@dataclass(frozen=True)
class WorldConfig:
    """Everything that shapes one simulated world."""

    speed: float = 1.0
    seed: int = 0
    host: str = "127.0.0.1"
    plc_port: int = 5020
    gnss_port: int = 5021
    mavlink_port: int = 5760
    control_port: int = 8090
    control: bool = True
    follow: str | None = None  # MAVLink URL of an external autopilot to follow (sim.follow)
    follow_timeout_s: float = 120.0  # how long to wait for its HOME_POSITION
    base: BaseParams = field(default_factory=BaseParams)
    weather: WeatherParams = field(default_factory=WeatherParams)
    power: PowerParams = field(default_factory=PowerParams)

    @classmethod
    def for_tests(cls, speed: float = 10.0, seed: int = 0, **kw: Any) -> WorldConfig:
        """Every port 0 (the OS picks), a speed factor for fast tests."""
        return cls(
            speed=speed, seed=seed, plc_port=0, gnss_port=0, mavlink_port=0, control_port=0, **kw
        )


class World:
    """The composed simulation; `async with World(cfg) as world:` serves it."""

    def __init__(self, config: WorldConfig | None = None) -> None:
        self.config = cfg = config or WorldConfig()
        self.clock = SimClock(cfg.speed)
        self.weather = Weather(cfg.seed, cfg.weather)
        self.power = PowerSystem(cfg.power)
        self.base = LandingBase(self.weather, self.power, cfg.base, seed=cfg.seed)
        self.plc = PlcServer(self.base, cfg.host, cfg.plc_port)
        self.parts: list[WorldPart] = []
        self.extra_routers: list[Any] = []
        self.ports: dict[str, int] = {}
        self._loop_task: asyncio.Task[None] | None = None
        self._control: Any = None
        self._control_task: asyncio.Task[None] | None = None
        self._t_last = 0.0

    def add_part(self, part: WorldPart) -> None:
        """Plug a part in (before `start()`)."""
        self.parts.append(part)

    def step(self, dt_sim: float) -> None:
        """Advance every model by `dt_sim` simulated seconds (in bounded sub-steps)."""
        while dt_sim > 1e-9:
            sub = min(dt_sim, MAX_SUBSTEP_SIM_S)
            dt_sim -= sub
            self.weather.advance_to(self.base.t_sim + sub)
            self.base.step(sub)
            for part in self.parts:
                part.step(sub)

    def restart_sensor_clocks(self, at: float = 0.0, parts: tuple[str, ...] = ()) -> None:
        """The sensors' timestamps (camera, IR; those of `parts` when named) count from `at` again,
        as after the world was restarted under a running agent, or the sensors rebooted; the
        models run on."""
        for part in self.parts:
            restart = getattr(part, "restart_stamps", None)
            if restart is not None and (not parts or part.name in parts):
                restart(at)

    async def _run_loop(self) -> None:
        while True:
            now = self.clock.now()
            try:
                self.step(now - self._t_last)
                self.base.tick_wall(time.monotonic())
            except Exception:
                log.exception("world: step failed")
            self._t_last = now
            await asyncio.sleep(STEP_WALL_S)

    async def start(self) -> None:
        """Start the PLC, every part, the step loop and the control interface."""
        self.base.tick_wall(time.monotonic())
        await self.plc.start()
        self.ports["plc"] = self.plc.port
        for part in self.parts:
            await part.start(self)
        self._t_last = self.clock.now()
        self._loop_task = asyncio.ensure_future(self._run_loop())
        if self.config.control:
            await self._start_control()
        log.info("world: serving %s (speed %.1fx)", self.ports, self.config.speed)

    async def _start_control(self) -> None:
        import uvicorn

        from sim.control import build_control_app

        routers = list(self.extra_routers)
        for part in self.parts:
            routers.extend(part.routers())
        app = build_control_app(self, extra_routers=routers)
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((self.config.host, self.config.control_port))
        self.ports["control"] = sock.getsockname()[1]
        config = uvicorn.Config(app, log_level="warning", lifespan="off")
        self._control = uvicorn.Server(config)
        self._control_task = asyncio.ensure_future(self._control.serve(sockets=[sock]))
        while not self._control.started:
            if self._control_task.done():
                self._control_task.result()
            await asyncio.sleep(0.01)

    async def stop(self) -> None:
        """Stop everything started by `start()`."""
        if self._control is not None and self._control_task is not None:
            self._control.should_exit = True
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._control_task, 5.0)
        await cancel_and_wait([self._loop_task])
        for part in reversed(self.parts):
            await part.stop()
        await self.plc.stop()

    async def __aenter__(self) -> World:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()


def parse_args(argv: Sequence[str] | None) -> WorldConfig:
    """Command-line flags -> WorldConfig."""
    ap = argparse.ArgumentParser(prog="aerobase sim world", description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--plc-port", type=int, default=5020)
    ap.add_argument("--gnss-port", type=int, default=5021)
    ap.add_argument("--mavlink-port", type=int, default=5760)
    ap.add_argument("--control-port", type=int, default=8090)
    ap.add_argument(
        "--follow",
        metavar="URL",
        help="simulate no vehicle: follow an external autopilot's reported pose over this read-only"
        " MAVLink connection (tcp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT); the base stands"
        " at its home",
    )
    ap.add_argument(
        "--follow-timeout",
        type=float,
        default=120.0,
        help="seconds to wait for the followed vehicle's HOME_POSITION",
    )
    a = ap.parse_args(argv)
    return WorldConfig(
        speed=a.speed,
        seed=a.seed,
        host=a.host,
        plc_port=a.plc_port,
        gnss_port=a.gnss_port,
        mavlink_port=a.mavlink_port,
        control_port=a.control_port,
        follow=a.follow,
        follow_timeout_s=a.follow_timeout,
    )


async def run(world: World, stop: asyncio.Event | None = None) -> None:
    """Serve `world` until `stop` is set (forever when None)."""
    async with world:
        print(f"aerobase sim world: serving {world.ports}", flush=True)
        await (stop or asyncio.Event()).wait()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase sim world`."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    world = World(parse_args(argv))
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run(world))
    return 0
