"""WebSocket routes: `/ws/asset` (daemons) and `/ws/operator` (people); the sessions do the work.

Each route is one coroutine over a `Socket` (frames.py), registered twice: in `native.ROUTES`,
how `aerobase server` serves it (straight from the transport), and as a FastAPI route over an
`AsgiSocket`, for any other ASGI server.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from fastapi import APIRouter, WebSocket

from server.deps import ServicesDep, principal_of
from server.kit.errors import AppError
from server.kit.principal import Principal
from server.kit.uow import unit_of_work
from server.realtime import native
from server.realtime.asgi_socket import AsgiSocket
from server.realtime.asset_session import ASSET_QUEUE, AssetSession
from server.realtime.frames import Socket, bearer_token
from server.realtime.operator_session import OPERATOR_QUEUE, OperatorSession
from server.services import Services

router = APIRouter()


async def _authenticate(sock: Socket, token: str | None, services: Services) -> Principal | None:
    """The caller, or None once the socket is closed with 4401."""
    try:
        async with unit_of_work(services.sessionmaker) as uow:
            principal, _ = await principal_of(uow, services.settings, token)
        return principal
    except AppError as err:
        await sock.accept()
        sock.close(4401, f"unauthorized: {err.message}"[:120])
        return None


async def serve_asset(sock: Socket, token: str | None, services: Services) -> None:
    """A daemon's session: hello/welcome, durable stream with acks, commands, RTCM."""
    principal = await _authenticate(sock, token, services)
    if principal is None:
        return
    await sock.accept()
    if principal.kind != "asset":
        sock.close(4401, "this socket is for assets; operators use /ws/operator")
        return
    asset_id, org_id = principal.asset_id, principal.organization_id
    if asset_id is None or org_id is None:  # every asset session carries both; never expected
        sock.close(4401, "this asset session has no asset or organisation")
        return
    await AssetSession(services, sock, principal, asset_id, org_id).serve()


async def serve_operator(sock: Socket, token: str | None, services: Services) -> None:
    """A person's live view: subscribe to assets of their organisation."""
    principal = await _authenticate(sock, token, services)
    if principal is None:
        return
    await sock.accept()
    if principal.kind != "user" or principal.organization_id is None:
        sock.close(4401, "this socket is for users of an organisation")
        return
    await OperatorSession(services, sock, principal).serve()


async def _native_asset(sock: Socket, handshake: native.Handshake, services: Services) -> None:
    await serve_asset(sock, handshake.token(), services)


async def _native_operator(sock: Socket, handshake: native.Handshake, services: Services) -> None:
    await serve_operator(sock, handshake.token(), services)


native.ROUTES["/ws/asset"] = native.Route(_native_asset, ASSET_QUEUE)
native.ROUTES["/ws/operator"] = native.Route(_native_operator, OPERATOR_QUEUE)


def _token(ws: WebSocket) -> str | None:
    return bearer_token(ws.headers.get("authorization", ""), ws.query_params.get("token"))


async def _over_asgi(
    ws: WebSocket,
    services: Services,
    queue: int,
    serve: Callable[[Socket, str | None, Services], Awaitable[None]],
) -> None:
    sock = AsgiSocket(ws, max_queue=queue, timeout_s=services.settings.ws_send_timeout_s)
    try:
        await serve(sock, _token(ws), services)
    finally:
        sock.close(1000)
        await sock.wait_closed()


@router.websocket("/ws/asset")
async def asset_socket(ws: WebSocket, services: ServicesDep) -> None:
    """`/ws/asset` under an ASGI server."""
    await _over_asgi(ws, services, ASSET_QUEUE, serve_asset)


@router.websocket("/ws/operator")
async def operator_socket(ws: WebSocket, services: ServicesDep) -> None:
    """`/ws/operator` under an ASGI server."""
    await _over_asgi(ws, services, OPERATOR_QUEUE, serve_operator)
