"""HTTP control of the simulated GNSS receiver: status and fault switches (an APIRouter factory)."""

from __future__ import annotations

from dataclasses import asdict

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from sim.gnss.receiver import GnssFaults, GnssReceiver


class GnssFaultsPatch(BaseModel):
    """A partial change of the fault switches; fields left out keep their value."""

    model_config = ConfigDict(extra="forbid")

    streaming: bool | None = None
    garbage_bytes: int | None = Field(default=None, ge=0, le=4096)
    corrupt_fraction: float | None = Field(default=None, ge=0.0, le=1.0)


def gnss_router(receiver: GnssReceiver, prefix: str = "/gnss") -> APIRouter:
    """Routes: GET {prefix} (status), POST {prefix}/faults (patch), POST {prefix}/faults/clear,
    POST {prefix}/disconnect (drop every client)."""
    router = APIRouter(prefix=prefix, tags=["sim: gnss"])

    @router.get("")
    async def status() -> dict[str, object]:
        """The receiver's configuration, position, epochs sent, faults and clients."""
        return {
            "config": receiver.config.model_dump(),
            "ecef_m": list(receiver.model.ecef),
            "message_types": list(receiver.model.message_types),
            "epochs_sent": receiver.epochs_sent,
            "last_epoch": receiver.last_epoch,
            "faults": receiver.faults.model_dump(),
            "clients": [asdict(c) for c in receiver.clients],
        }

    @router.post("/faults")
    async def set_faults(patch: GnssFaultsPatch) -> GnssFaults:
        """Change some fault switches."""
        return receiver.set_faults(**patch.model_dump(exclude_none=True))

    @router.post("/faults/clear")
    async def clear_faults() -> GnssFaults:
        """Back to a clean, streaming receiver."""
        return receiver.set_faults(**GnssFaults().model_dump())

    @router.post("/disconnect")
    async def disconnect() -> dict[str, int]:
        """Drop every connected client, as a receiver reboot would."""
        return {"disconnected": await receiver.disconnect_clients()}

    return router
