"""Pages of lists, one mechanism for every list endpoint.

In: `limit` and `offset` query parameters (bounds checked, 422 outside them). Out: the page's rows
and the total of the same filtered query, read in one statement (a scalar subquery), so the total
and the rows come from one snapshot. On the answer: `X-Total-Count` and an RFC 8288 `Link` header
(`rel="next"`, `rel="prev"`) whose targets are the same path with the same filters. The body stays
a JSON array.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Generic, TypeVar
from urllib.parse import urlencode

from fastapi import Depends, Query, Request, Response
from sqlalchemy import Select, func, select
from sqlalchemy.ext.asyncio import AsyncSession

MAX_OFFSET = 10**9
TOTAL_HEADER = "X-Total-Count"
T = TypeVar("T")
M = TypeVar("M")


@dataclass(frozen=True)
class Page:
    """Which slice of an ordered list: `limit` rows after skipping `offset`."""

    limit: int
    offset: int = 0


@dataclass(frozen=True)
class Paged(Generic[T]):
    """A page of rows and how many rows the whole filtered list has."""

    items: list[T]
    total: int


def _count(stmt: Select[Any]) -> Select[int]:
    return select(func.count()).select_from(stmt.order_by(None).subquery())


async def paginate_rows(db: AsyncSession, stmt: Select[Any], page: Page) -> Paged[tuple[Any, ...]]:
    """One page of an ordered SELECT, as row tuples, with the total of the same SELECT.

    The total rides on every row as an uncorrelated scalar subquery (evaluated once): one
    statement, one snapshot, and the count's own plan (an index-only scan where it can, where
    `count(*) OVER ()` would drag every column of every row through the window)."""
    counted = stmt.add_columns(_count(stmt).scalar_subquery().label("_total"))
    rows = (await db.execute(counted.limit(page.limit).offset(page.offset))).all()
    if rows:
        return Paged([tuple(r[:-1]) for r in rows], int(rows[0][-1]))
    # past the end (or nothing at all): no row carries the total, count it
    total = 0 if page.offset == 0 else int((await db.execute(_count(stmt))).scalar_one())
    return Paged([], total)


async def paginate(db: AsyncSession, stmt: Select[M], page: Page) -> Paged[M]:
    """One page of an ordered single-entity SELECT, with the total of the same SELECT."""
    found = await paginate_rows(db, stmt, page)
    return Paged([row[0] for row in found.items], found.total)


def page_of(items: list[T], page: Page) -> Paged[T]:
    """A page cut from a list already in memory (a list of at most a few rows)."""
    return Paged(items[page.offset : page.offset + page.limit], len(items))


class Pager:
    """The page a list request asks for, and the headers that place the answer in the whole."""

    def __init__(self, request: Request, response: Response, page: Page) -> None:
        self.request = request
        self.response = response
        self.page = page

    def _target(self, offset: int) -> str:
        """The same path and filters, another offset (a relative reference, RFC 3986 4.2)."""
        query = [(k, v) for k, v in self.request.query_params.multi_items() if k not in PAGING]
        query += [("limit", str(self.page.limit)), ("offset", str(offset))]
        return f"{self.request.url.path}?{urlencode(query)}"

    def respond(self, total: int) -> None:
        """Set `X-Total-Count` and `Link` (next while rows remain, prev while not at the start)."""
        limit, offset = self.page.limit, self.page.offset
        self.response.headers[TOTAL_HEADER] = str(total)
        links = []
        if offset + limit < total:
            links.append(f'<{self._target(offset + limit)}>; rel="next"')
        if offset > 0:
            links.append(f'<{self._target(max(0, min(offset, total) - limit))}>; rel="prev"')
        if links:
            self.response.headers["Link"] = ", ".join(links)


PAGING = ("limit", "offset")


def pager(default: int = 100, maximum: int = 1000) -> Callable[..., Pager]:
    """A dependency reading `limit` (1..maximum, default `default`) and `offset` (0..1e9)."""

    def dependency(
        request: Request,
        response: Response,
        limit: int = Query(default, ge=1, le=maximum, description=f"rows per page (1..{maximum})"),
        offset: int = Query(0, ge=0, le=MAX_OFFSET, description="rows to skip"),
    ) -> Pager:
        return Pager(request, response, Page(limit, offset))

    return dependency


# the headers a list answer carries (for OpenAPI)
PAGE_HEADERS: dict[str, Any] = {
    TOTAL_HEADER: {
        "description": "how many rows the whole filtered list has",
        "schema": {"type": "integer", "minimum": 0},
    },
    "Link": {
        "description": 'RFC 8288: `<...>; rel="next"`, `<...>; rel="prev"` (same path and filters)',
        "schema": {"type": "string"},
    },
}
# the answer of a list endpoint in OpenAPI: its 200 carries the two headers
PAGED: dict[int | str, dict[str, Any]] = {200: {"headers": PAGE_HEADERS}}
# the usual page: 100 rows by default, at most 1000
Paging = Annotated[Pager, Depends(pager())]
