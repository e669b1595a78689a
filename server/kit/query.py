"""Unknown query parameters are refused (422), so a misspelt `limt=10` is not silently ignored."""

from __future__ import annotations

from fastapi.dependencies.models import Dependant
from starlette.requests import HTTPConnection

from server.kit.errors import Unprocessable


def _declared(dependant: Dependant) -> set[str]:
    """The query parameter names a route takes, its dependencies' included."""
    names = {p.alias for p in dependant.query_params}
    for sub in dependant.dependencies:
        names |= _declared(sub)
    return names


async def known_query_only(connection: HTTPConnection) -> None:
    """An app-wide dependency: 422 naming every query parameter the matched route does not take.
    WebSocket routes are left alone (their `token` comes from the socket's own handshake)."""
    if connection.scope["type"] != "http":
        return
    dependant = getattr(connection.scope.get("route"), "dependant", None)
    if dependant is None:
        return
    unknown = sorted(set(connection.query_params) - _declared(dependant))
    if unknown:
        raise Unprocessable(
            f"unknown query parameter{'s' if len(unknown) > 1 else ''}: {', '.join(unknown)}",
            details=[
                {
                    "loc": ["query", name],
                    "msg": "not a parameter of this route",
                    "type": "extra_forbidden",
                }
                for name in unknown
            ],
        )
