"""All SQL of organisations, users and memberships."""

from __future__ import annotations

import uuid

from sqlalchemy import select, update
from sqlalchemy.ext.asyncio import AsyncSession

from server.kit.paging import Page, Paged, paginate, paginate_rows
from server.kit.scope import ScopedRepository
from server.organizations.models import Membership, Organization, User


class OrganizationRepository:
    """Organisations: all of them for a superuser, one's own otherwise (see service)."""

    def __init__(self, db: AsyncSession) -> None:
        self.db = db

    async def by_name(self, name: str) -> Organization | None:
        """The organisation with this name."""
        stmt = select(Organization).where(Organization.name == name)  # unscoped: names are global
        return (await self.db.execute(stmt)).scalar_one_or_none()

    async def by_id(self, org_id: uuid.UUID) -> Organization | None:
        """The organisation with this id."""
        return await self.db.get(Organization, org_id)

    async def all(self, page: Page) -> Paged[Organization]:
        """Every organisation (superusers only)."""
        stmt = select(Organization).order_by(
            Organization.created_at, Organization.id
        )  # unscoped: superuser
        return await paginate(self.db, stmt, page)


class UserRepository:
    """Users by identity (e-mail, id): used by login and the admin CLI."""

    def __init__(self, db: AsyncSession) -> None:
        self.db = db

    async def by_email(self, email: str, *, lock: bool = False) -> User | None:
        """The user with this e-mail, optionally locked for the rest of the transaction."""
        stmt = select(User).where(User.email == email.lower())  # unscoped: identity lookup
        if lock:
            stmt = stmt.with_for_update()
        return (await self.db.execute(stmt)).scalar_one_or_none()

    async def claim_for_login(self, user_id: uuid.UUID, password_hash: str) -> bool:
        """Hold the user for a login's transaction on condition that their password is still
        the one checked (False: changed since); a write that changes nothing, for the reasons
        of `AssetRepository.claim_for_login`."""
        stmt = (
            update(User)  # unscoped: identity lookup, before any caller
            .where(User.id == user_id, User.password_hash == password_hash)
            .values(password_hash=User.password_hash)
            .execution_options(synchronize_session=False)
        )
        return bool((await self.db.execute(stmt)).rowcount == 1)  # type: ignore[attr-defined]

    async def memberships(self, user_id: uuid.UUID) -> list[tuple[Membership, Organization]]:
        """Every membership of a user with its organisation."""
        stmt = (
            select(Membership, Organization)  # unscoped: a user's own memberships
            .join(Organization, Organization.id == Membership.organization_id)
            .where(Membership.user_id == user_id)
            .order_by(Membership.created_at)
        )
        return [(m, o) for m, o in (await self.db.execute(stmt)).all()]


class MembershipRepository(ScopedRepository[Membership]):
    """Members of the caller's organisation."""

    model = Membership
    noun = "user"

    async def with_users(self, page: Page) -> Paged[tuple[Membership, User]]:
        """Members and their users, oldest first."""
        stmt = (
            self.select()
            .add_columns(User)
            .join(User, User.id == Membership.user_id)
            .order_by(Membership.created_at, Membership.id)
        )
        found = await paginate_rows(self.db, stmt, page)
        return Paged([(m, u) for m, u in found.items], found.total)

    async def of_user(
        self, user_id: uuid.UUID, *, lock: bool = False
    ) -> tuple[Membership, User] | None:
        """The membership of one user in the caller's organisation (`lock`: the membership's row,
        for the rest of the transaction, on PostgreSQL)."""
        stmt = (
            self.select()
            .add_columns(User)
            .join(User, User.id == Membership.user_id)
            .where(Membership.user_id == user_id)
        )
        if lock:
            stmt = stmt.with_for_update(of=Membership, key_share=True).execution_options(
                populate_existing=True
            )
        row = (await self.db.execute(stmt)).first()
        return (row[0], row[1]) if row else None
