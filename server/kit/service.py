"""The one shape of a domain service: the request's unit of work and the caller."""

from __future__ import annotations

from server.kit.principal import Principal
from server.kit.uow import UnitOfWork


class Service:
    """Base of every domain service.

    A service builds the repositories it needs from its unit of work and its principal (so every
    read is scoped to the caller's organisation), stages changes (flush, never commit), writes
    its audit record through `server.audit.service.record`, and registers what must follow the
    commit (session ends, broker nudges) on the unit of work. The request's boundary commits.
    """

    def __init__(self, uow: UnitOfWork, principal: Principal) -> None:
        self.uow = uow
        self.db = uow.db
        self.principal = principal
