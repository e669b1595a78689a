"""The simulator's control interface: fault injection, forced weather and ground truth (HTTP/JSON).

Served by uvicorn inside the world process (`aerobase sim world --control-port 8090`).
Every POST takes a JSON object and answers `{"ok": true, "state": <ground truth>}`;
errors answer `{"error": {"code", "message"}}` with 400/404.

| method, path                  | body                                                    |
|-------------------------------|---------------------------------------------------------|
| GET  /health                  | -> {"ok": true, "ports": {...}, "speed": x}             |
| GET  /state                   | -> ground truth of the base (positions, faults, ...)    |
| POST /faults/stall            | {"axis": "panels"|"lift", "on": true, "immediate": false} |
| POST /faults/link             | {"mode": "normal"|"cut"|"freeze"}                       |
| POST /faults/estop            | {"on": true}                                            |
| POST /faults/cpu_halt         | {"on": true}  (outputs drop; heartbeat and commands freeze) |
| POST /faults/weather_sensor   | {"on": true}                                            |
| POST /faults/charger          | {"on": true}                                            |
| POST /faults/grid             | {"present": false}                                      |
| POST /weather/force           | {"wind_mps"?, "gust_mps"?, "direction_deg"?, "rain_mm_h"?, "temperature_c"?, "humidity_pct"?} (null releases one) |
| POST /weather/release         | {}                                                      |
| POST /weather/scenario        | {"name": "calm"|"windy"|"storm"|"rain_spell"|"freezing"} |
| POST /pad                     | {"mass_g": 1500, "contacts_seated": true, "uav_soc"?: 0.4} |

Other parts add their own routes: `build_control_app(world, extra_routers=[router, ...])`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from fastapi import APIRouter, FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict

from sim.plc import LinkMode
from sim.weather import SCENARIOS

if TYPE_CHECKING:
    from sim.world import World


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


class StallBody(_Body):
    """Jam (or free) a motor."""

    axis: Literal["panels", "lift"]
    on: bool = True
    immediate: bool = False


class LinkBody(_Body):
    """Break the Modbus link."""

    mode: LinkMode


class OnBody(_Body):
    """Switch a fault on or off."""

    on: bool = True


class GridBody(_Body):
    """Grid presence."""

    present: bool


class WeatherForceBody(_Body):
    """Forced weather values; fields left out are unchanged, null releases one."""

    wind_mps: float | None = None
    gust_mps: float | None = None
    direction_deg: float | None = None
    rain_mm_h: float | None = None
    temperature_c: float | None = None
    humidity_pct: float | None = None


class ScenarioBody(_Body):
    """A named weather scenario."""

    name: str


class PadBody(_Body):
    """What stands on the pad."""

    mass_g: float
    contacts_seated: bool = False
    uav_soc: float | None = None


def _error(status: int, code: str, message: str) -> JSONResponse:
    return JSONResponse({"error": {"code": code, "message": message}}, status_code=status)


def base_router(world: World) -> APIRouter:
    """Routes for the landing base and the weather."""
    r = APIRouter()
    base = world.base

    def ok() -> dict[str, Any]:
        """The common answer: ok plus the ground truth."""
        return {"ok": True, "state": base.ground_truth() | {"link": str(world.plc.link)}}

    @r.get("/health")
    def health() -> dict[str, Any]:
        """Bound ports and speed factor."""
        return {"ok": True, "ports": world.ports, "speed": world.config.speed}

    @r.get("/state")
    def state() -> dict[str, Any]:
        """Ground truth of the base."""
        return ok()["state"]

    @r.post("/faults/stall")
    def stall(body: StallBody) -> dict[str, Any]:
        """Jam or free a motor (optionally latching its stall at once)."""
        base.inject_stall(body.axis, body.on, body.immediate)
        return ok()

    @r.post("/faults/link")
    def link(body: LinkBody) -> dict[str, Any]:
        """Cut, freeze or restore the Modbus link."""
        world.plc.set_link(body.mode)
        return ok()

    @r.post("/faults/estop")
    def estop(body: OnBody) -> dict[str, Any]:
        """Press or release the E-stop."""
        base.set_estop(body.on)
        return ok()

    @r.post("/faults/cpu_halt")
    def cpu_halt(body: OnBody) -> dict[str, Any]:
        """Halt or restart the PLC CPU."""
        base.set_cpu_halt(body.on)
        return ok()

    @r.post("/faults/weather_sensor")
    def weather_sensor(body: OnBody) -> dict[str, Any]:
        """Fail or repair the weather sensors."""
        world.weather.sensor_fault = body.on
        return ok()

    @r.post("/faults/charger")
    def charger(body: OnBody) -> dict[str, Any]:
        """Fail or repair the charger."""
        base.charger.fault = body.on
        return ok()

    @r.post("/faults/grid")
    def grid(body: GridBody) -> dict[str, Any]:
        """Connect or disconnect the grid."""
        world.power.grid_present = body.present
        return ok()

    @r.post("/weather/force")
    def force(body: WeatherForceBody) -> dict[str, Any]:
        """Force weather values (null releases one)."""
        world.weather.force(**body.model_dump(exclude_unset=True))
        return ok()

    @r.post("/weather/release")
    def release() -> dict[str, Any]:
        """Release every forced weather value."""
        world.weather.release()
        return ok()

    @r.post("/weather/scenario")
    def scenario(body: ScenarioBody) -> Any:
        """Start a scripted weather scenario."""
        if body.name not in SCENARIOS:
            return _error(404, "unknown_scenario", f"known scenarios: {sorted(SCENARIOS)}")
        world.weather.run_scenario(body.name)
        return ok()

    @r.post("/pad")
    def pad(body: PadBody) -> dict[str, Any]:
        """Put a mass on the pad (or remove it), seat the contacts, set the UAV's battery."""
        base.set_pad_load(body.mass_g, body.contacts_seated)
        if body.uav_soc is not None:
            base.set_uav_battery(body.uav_soc)
        return ok()

    return r


def build_control_app(world: World, extra_routers: list[APIRouter] | None = None) -> FastAPI:
    """The control app for `world`, with the base's routes plus `extra_routers`."""
    app = FastAPI(title="Aerobase simulator control", docs_url="/docs")

    @app.exception_handler(Exception)
    async def _unhandled(request: Request, exc: Exception) -> JSONResponse:
        return _error(500, "internal", str(exc))

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse(
            {
                "error": {
                    "code": "invalid",
                    "message": "invalid body",
                    "details": jsonable_encoder(exc.errors()),
                }
            },
            status_code=400,
        )

    app.include_router(base_router(world))
    for router in extra_routers or []:
        app.include_router(router)
    return app
