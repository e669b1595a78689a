"""Simulated IR-beacon sensor (like an IRLock / Pixy): angles to the pad's beacon at 50 Hz over UDP.

The sensor looks down with the camera's axes (x right, y towards the tail, z down — image
convention) and reports the beacon's direction as two angles: angle_x = atan2(x, z) and
angle_y = atan2(y, z), with Gaussian noise, when the beacon is within the field of view and the
detection range; otherwise it reports "not detected".

Where readings go: either to a configured (host, port), or — when the sensor is given no
destination — to every address that has sent any datagram to the sensor's own UDP port (a
subscription, as a MAVLink UDP endpoint replies to whoever talks to it; at most 8, kept until the
sensor stops). In the world the sensor serves on `world.ports["ir"]`.

Datagram (one reading, 28 bytes, little-endian)::

    struct "<4sBBHIdff": magic b"ABIR", version 1, flags (bit 0: beacon detected), reserved 0,
                         seq (uint32), capture_ts (float64 seconds on the world's clock),
                         angle_x, angle_y (float32 radians; 0 when not detected)
"""

from __future__ import annotations

import asyncio
import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from asynckit.tasks import cancel_and_wait
from sim.camera.render import CAM_FROM_BODY, Pose, rotation_world_from_body

log = logging.getLogger(__name__)

DATAGRAM = struct.Struct("<4sBBHIdff")
MAGIC = b"ABIR"
VERSION = 1


@dataclass(frozen=True)
class IrSensorConfig:
    """Sensor characteristics: rate, noise, field of view, range, beacon position on the pad."""

    rate_hz: float = 50.0
    noise_rad: float = 0.002
    fov_deg: float = 60.0
    max_range_m: float = 15.0
    beacon_xy: tuple[float, float] = (0.0, 0.0)


def ir_reading(
    pose: Pose, config: IrSensorConfig, rng: np.random.Generator | None = None
) -> tuple[bool, float, float]:
    """(detected, angle_x, angle_y) of the beacon seen from `pose` (noise drawn from `rng`)."""
    n, e, up, roll, pitch, yaw = pose
    r_cw = CAM_FROM_BODY @ rotation_world_from_body(roll, pitch, yaw).T
    rel = np.array([config.beacon_xy[0] - n, config.beacon_xy[1] - e, up])
    v = r_cw @ rel
    dist = float(np.linalg.norm(rel))
    if v[2] <= 0 or dist > config.max_range_m:
        return False, 0.0, 0.0
    ax, ay = math.atan2(v[0], v[2]), math.atan2(v[1], v[2])
    half = math.radians(config.fov_deg) / 2
    if abs(ax) > half or abs(ay) > half:
        return False, 0.0, 0.0
    if rng is not None and config.noise_rad > 0:
        ax += float(rng.normal(0, config.noise_rad))
        ay += float(rng.normal(0, config.noise_rad))
    return True, ax, ay


def encode_reading(seq: int, capture_ts: float, detected: bool, ax: float, ay: float) -> bytes:
    """One datagram."""
    return DATAGRAM.pack(
        MAGIC, VERSION, 1 if detected else 0, 0, seq & 0xFFFFFFFF, capture_ts, ax, ay
    )


class _Subscriptions(asyncio.DatagramProtocol):
    """Remembers who sent us a datagram: they get the readings."""

    MAX = 8

    def __init__(self) -> None:
        self.addrs: list[tuple[str, int]] = []

    def datagram_received(self, data: bytes, addr) -> None:
        """Subscribe the sender."""
        addr = (addr[0], addr[1])
        if addr not in self.addrs:
            self.addrs = [*self.addrs, addr][-self.MAX :]
            log.info("IR sensor: subscriber %s", addr)


class IrBeaconSensor:
    """Sends a reading every 1/rate_hz simulated seconds over UDP, to `dest` or to subscribers."""

    IDLE_POLL_S = 0.05  # wall seconds between looks for a first subscriber

    def __init__(
        self,
        pose_fn: Callable[[], Pose],
        clock,
        dest: tuple[str, int] | None = None,
        config: IrSensorConfig | None = None,
        seed: int = 0,
        host: str = "127.0.0.1",
        port: int = 0,
    ) -> None:
        self.pose_fn = pose_fn
        self.clock = clock
        self.dest = dest
        self.config = config or IrSensorConfig()
        self.host, self.port = host, port
        self.sent = 0
        self.stamp_offset = 0.0  # reading timestamps are the clock's seconds less this
        self._rng = np.random.default_rng(seed)
        self._subs = _Subscriptions()
        self._transport: asyncio.DatagramTransport | None = None
        self._task: asyncio.Task | None = None

    async def start(self) -> int:
        """Bind the sensor's UDP port and start sending; returns the bound port."""
        loop = asyncio.get_running_loop()
        self._transport, _ = await loop.create_datagram_endpoint(
            lambda: self._subs, local_addr=(self.host, self.port)
        )
        self.port = self._transport.get_extra_info("sockname")[1]
        self._task = asyncio.create_task(self._run(), name="ir-sensor")
        return self.port

    def restart_stamps(self, at: float = 0.0) -> None:
        """Reading timestamps count from `at` again (the sensor rebooted, or the world restarted
        under a running agent); the schedule runs on."""
        self.stamp_offset = self.clock.now() - at

    async def stop(self) -> None:
        """Stop sending and close the socket."""
        await cancel_and_wait([self._task])
        if self._transport:
            self._transport.close()

    async def _run(self) -> None:
        period = 1.0 / self.config.rate_hz
        next_t = self.clock.now()
        seq = 0
        while True:
            if self.dest is None and not self._subs.addrs:  # nobody listens: idle cheaply
                await asyncio.sleep(self.IDLE_POLL_S)
                next_t = self.clock.now()
                continue
            next_t += period
            await self.clock.sleep(next_t - self.clock.now())
            if self.clock.now() - next_t > period:
                next_t = self.clock.now()
            try:
                ts = self.clock.now() - self.stamp_offset
                detected, ax, ay = ir_reading(self.pose_fn(), self.config, self._rng)
                assert self._transport is not None
                data = encode_reading(seq, ts, detected, ax, ay)
                for addr in [self.dest] if self.dest else self._subs.addrs:
                    self._transport.sendto(data, addr)
                seq += 1
                self.sent += 1
            except Exception:
                log.exception("IR reading failed; skipping")


class IrPart:
    """The IR-beacon sensor as a world part: serves on an OS-chosen UDP port, recorded in
    `world.ports["ir"]`; readings go to whoever subscribes. `pose_fn` is the vehicle's true pose
    relative to the pad centre (camera height as `up`)."""

    name = "ir"

    def __init__(
        self, pose_fn: Callable[[], Pose], config: IrSensorConfig | None = None, port: int = 0
    ) -> None:
        self.pose_fn = pose_fn
        self.config = config
        self.port = port
        self.sensor: IrBeaconSensor | None = None

    async def start(self, world) -> None:
        """Start the sensor on the world's clock."""
        self.sensor = IrBeaconSensor(
            self.pose_fn,
            world.clock,
            None,
            self.config,
            world.config.seed,
            world.config.host,
            self.port,
        )
        world.ports["ir"] = await self.sensor.start()

    def restart_stamps(self, at: float = 0.0) -> None:
        """The sensor's timestamps count from `at` again."""
        if self.sensor is not None:
            self.sensor.restart_stamps(at)

    async def stop(self) -> None:
        """Stop the sensor."""
        if self.sensor is not None:
            await self.sensor.stop()

    def step(self, dt_sim: float) -> None:
        """Nothing to integrate: the sensor samples the pose on its own schedule."""

    def routers(self) -> list:
        """No control endpoints."""
        return []
