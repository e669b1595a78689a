"""WebSocket routes: `/ws/asset` (daemons) and `/ws/operator` (people); the sessions do the work."""

from __future__ import annotations

from fastapi import APIRouter, WebSocket

from server.deps import ServicesDep, principal_of
from server.kit.errors import AppError
from server.kit.principal import Principal
from server.kit.uow import unit_of_work
from server.realtime.asset_session import AssetSession
from server.realtime.operator_session import OperatorSession
from server.services import Services

router = APIRouter()


def _token(ws: WebSocket) -> str | None:
    scheme, _, value = ws.headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return ws.query_params.get("token")


async def _authenticate(ws: WebSocket, services: Services) -> Principal | None:
    """The caller, or None once the socket is closed with 4401."""
    try:
        async with unit_of_work(services.sessionmaker) as uow:
            principal, _ = await principal_of(uow, services.settings, _token(ws))
        return principal
    except AppError as err:
        await ws.accept()
        await ws.close(4401, f"unauthorized: {err.message}"[:120])
        return None


@router.websocket("/ws/asset")
async def asset_socket(ws: WebSocket, services: ServicesDep) -> None:
    """A daemon's session: hello/welcome, durable stream with acks, commands, RTCM."""
    principal = await _authenticate(ws, services)
    if principal is None:
        return
    await ws.accept()
    if principal.kind != "asset":
        await ws.close(4401, "this socket is for assets; operators use /ws/operator")
        return
    asset_id, org_id = principal.asset_id, principal.organization_id
    if asset_id is None or org_id is None:  # every asset session carries both; never expected
        await ws.close(4401, "this asset session has no asset or organisation")
        return
    await AssetSession(services, ws, principal, asset_id, org_id).serve()


@router.websocket("/ws/operator")
async def operator_socket(ws: WebSocket, services: ServicesDep) -> None:
    """A person's live view: subscribe to assets of their organisation."""
    principal = await _authenticate(ws, services)
    if principal is None:
        return
    await ws.accept()
    if principal.kind != "user" or principal.organization_id is None:
        await ws.close(4401, "this socket is for users of an organisation")
        return
    await OperatorSession(services, ws, principal).serve()
