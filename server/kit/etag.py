"""Strong ETags and `If-Match` on the resources operators edit, so concurrent edits are detected.

An editable row carries a `version` column that the ORM raises on every UPDATE of the row
(`Versioned`, SQLAlchemy's version counter) and checks in the UPDATE's or DELETE's WHERE clause.
Its ETag is `"<version>"`. GET, POST and PATCH answers carry it; a PATCH or DELETE with
`If-Match` is checked against the row it is about to change, read under a row lock on
PostgreSQL: no match -> 412 `precondition_failed`. A write that loses a race anyway (SQLite takes
no row lock) fails the version check in its WHERE clause: 412 with `If-Match`, 409
`edit_conflict` without. Without `If-Match` an edit applies to the current version.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, Header, Response
from sqlalchemy.orm import Mapped, declared_attr, mapped_column

from server.kit.errors import BadRequest, EditConflict, PreconditionFailed
from server.kit.openapi import declares

ETAG_HEADER = "ETag"
_TAG = re.compile(r'\s*(W/)?"([\x21\x23-\x7e\x80-\xff]*)"\s*(?:,|$)')


class Versioned:
    """A version counter: 1 on insert, raised by every UPDATE, checked by UPDATE and DELETE."""

    version: Mapped[int] = mapped_column(server_default="1")

    @declared_attr.directive
    def __mapper_args__(cls) -> dict[str, Any]:
        return {"version_id_col": cls.version}


def etag(version: int) -> str:
    """The strong entity tag of a resource at this version."""
    return f'"{version}"'


def parse_if_match(value: str) -> tuple[str, ...]:
    """The entity tags of an `If-Match` value (RFC 9110 13.1.1): `*`, or strong tags only
    (a weak tag never matches strongly, so it is kept out). 400 when it is not such a list."""
    if value.strip() == "*":
        return ("*",)
    tags, pos = [], 0
    while pos < len(value):
        found = _TAG.match(value, pos)
        if found is None or found.end() == pos:
            raise BadRequest(f'If-Match: expected "*" or a list of quoted entity tags: {value!r}')
        if not found.group(1):
            tags.append(f'"{found.group(2)}"')
        pos = found.end()
    return tuple(tags)


@dataclass(frozen=True)
class IfMatch:
    """A request's `If-Match` precondition; `tags` is None when the request has none."""

    tags: tuple[str, ...] | None = None

    def check(self, version: int, what: str) -> None:
        """Raise PreconditionFailed unless the resource at `version` satisfies the precondition."""
        if self.tags is None or "*" in self.tags or etag(version) in self.tags:
            return
        raise PreconditionFailed(
            f"{what} has changed since it was read (now {etag(version)}, If-Match "
            f"{', '.join(self.tags) or 'named no strong tag'}): read it again and reapply the edit",
            details={"current_etag": etag(version)},
        )


@declares(BadRequest, PreconditionFailed, EditConflict)  # every route reading it documents them
def if_match(
    value: Annotated[
        str | None,
        Header(
            alias="If-Match",
            description='the ETag the edit is based on ("*": any version); 412 when it changed',
        ),
    ] = None,
) -> IfMatch:
    """The dependency reading `If-Match`."""
    return IfMatch(None if value is None else parse_if_match(value))


IfMatchDep = Annotated[IfMatch, Depends(if_match)]
NO_PRECONDITION = IfMatch()


def tag(response: Response, version: int) -> None:
    """Put the resource's ETag on the answer."""
    response.headers[ETAG_HEADER] = etag(version)


# OpenAPI: the answers that carry the ETag (the edits' 400/409/412 come from `if_match`)
ETAG_HEADERS: dict[str, Any] = {
    ETAG_HEADER: {
        "description": "strong entity tag of this version; send it back as If-Match",
        "schema": {"type": "string"},
    }
}
TAGGED: dict[int | str, dict[str, Any]] = {200: {"headers": ETAG_HEADERS}}
CREATED_TAGGED: dict[int | str, dict[str, Any]] = {201: {"headers": ETAG_HEADERS}}
