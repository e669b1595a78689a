"""Decisions about organisations, users and roles (shared by the API and the admin CLI)."""

from __future__ import annotations

import asyncio
import uuid

from sqlalchemy.ext.asyncio import AsyncSession

from server.audit.service import record
from server.auth.service import SessionService
from server.config import Settings
from server.kit.errors import Conflict, Forbidden, NotFound
from server.kit.etag import NO_PRECONDITION, IfMatch
from server.kit.paging import Page, Paged, page_of
from server.kit.principal import Principal, Role
from server.kit.security import Passwords
from server.kit.service import Service
from server.kit.uow import UnitOfWork
from server.organizations.models import Membership, Organization, User
from server.organizations.repository import (
    MembershipRepository,
    OrganizationRepository,
    UserRepository,
)


async def create_organization(db: AsyncSession, name: str) -> Organization:
    """A new organisation; its name must be free."""
    if await OrganizationRepository(db).by_name(name):
        raise Conflict(f"an organisation named {name!r} already exists", code="name_taken")
    org = Organization(name=name)
    db.add(org)
    await db.flush()
    return org


async def create_user(
    db: AsyncSession, passwords: Passwords, *, email: str, password: str, is_superuser: bool = False
) -> User:
    """A new user; the e-mail must be free."""
    if await UserRepository(db).by_email(email):
        raise Conflict(f"a user with e-mail {email} already exists", code="email_taken")
    user = User(
        email=email.lower(),
        password_hash=await asyncio.to_thread(passwords.hash, password),
        is_superuser=is_superuser,
    )
    db.add(user)
    await db.flush()
    return user


async def add_member(
    db: AsyncSession, org_id: uuid.UUID, user_id: uuid.UUID, role: Role
) -> Membership:
    """Give a user a role in an organisation."""
    membership = Membership(organization_id=org_id, user_id=user_id, role=role)
    db.add(membership)
    await db.flush()
    return membership


async def org_by_name(db: AsyncSession, name: str) -> Organization:
    """The organisation with this name, else NotFound."""
    org = await OrganizationRepository(db).by_name(name)
    if org is None:
        raise NotFound(f"no organisation named {name!r}")
    return org


class OrganizationService(Service):
    """Organisations and the members of the caller's organisation."""

    def __init__(self, uow: UnitOfWork, principal: Principal, settings: Settings) -> None:
        super().__init__(uow, principal)
        self.settings = settings
        self.orgs = OrganizationRepository(self.db)
        self.members = MembershipRepository(self.db, principal)

    async def create_organization(self, name: str) -> Organization:
        """A new organisation (the caller is a superuser)."""
        org = await create_organization(self.db, name)
        await record(
            self.uow,
            self.principal,
            "organization.created",
            target=org.name,
            organization_id=org.id,
        )
        return org

    async def organizations(self, page: Page) -> Paged[Organization]:
        """Every organisation for a superuser, one's own otherwise."""
        if self.principal.is_superuser:
            return await self.orgs.all(page)
        org = await self.orgs.by_id(self.principal.organization_id)  # type: ignore[arg-type]
        return page_of([org] if org else [], page)

    async def organization(self, organization_id: uuid.UUID) -> Organization:
        """One's own organisation, or any for a superuser; NotFound otherwise."""
        org = await self.orgs.by_id(organization_id)
        if org is None or (
            org.id != self.principal.organization_id and not self.principal.is_superuser
        ):
            raise NotFound(f"organisation {organization_id} not found")
        return org

    async def users(self, page: Page) -> Paged[tuple[Membership, User]]:
        """Members of the caller's organisation, oldest first."""
        return await self.members.with_users(page)

    async def user(self, user_id: uuid.UUID, *, lock: bool = False) -> tuple[Membership, User]:
        """One member of the caller's organisation (`lock`: its membership, to edit it);
        NotFound otherwise."""
        found = await self.members.of_user(user_id, lock=lock)
        if found is None:
            raise NotFound(f"user {user_id} not found")
        return found

    async def create_user(
        self, passwords: Passwords, *, email: str, password: str, role: Role
    ) -> tuple[Membership, User]:
        """A new user, member of the caller's organisation."""
        org_id = self.principal.organization_id
        user = await create_user(self.db, passwords, email=email, password=password)
        m = await add_member(self.db, org_id, user.id, role)  # type: ignore[arg-type]
        await record(self.uow, self.principal, "user.created", target=user.email, role=role.value)
        return m, user

    async def update_user(
        self,
        user_id: uuid.UUID,
        *,
        role: Role | None,
        is_active: bool | None,
        expect: IfMatch = NO_PRECONDITION,
    ) -> tuple[Membership, User]:
        """Change a member's role, or disable them in this organisation (their sessions here end;
        their other organisations are not this admin's to close). PreconditionFailed when
        `expect` names another version of the membership."""
        m, u = await self.user(user_id, lock=True)
        expect.check(m.version, f"user {u.id}")
        if u.id == self.principal.user_id and role not in (None, Role.admin):
            raise Conflict("you cannot lower your own role", code="self_demotion")
        if u.id == self.principal.user_id and is_active is False:
            raise Conflict("you cannot disable yourself", code="self_disable")
        if role is not None:
            m.role = role
        if is_active is not None:
            m.is_active = is_active
            if not is_active:
                await SessionService(self.uow, self.settings).end_all_for_user(
                    u.id, "disabled", self.principal.organization_id
                )
        changes = {k: v for k, v in (("role", role), ("is_active", is_active)) if v is not None}
        await record(self.uow, self.principal, "user.updated", target=u.email, changes=changes)
        await self.db.flush()
        return m, u

    async def reset_password(self, passwords: Passwords, user_id: uuid.UUID, new: str) -> int:
        """Give a member a new password (an administrator's reset: no current password asked);
        every session of theirs ends; how many did. Refused for oneself (the change route asks
        for the current password), for a platform superuser and for a member of another
        organisation too, unless the caller is a superuser: an organisation's admin must not
        take over an account that opens more than their own organisation."""
        m, u = await self.user(user_id, lock=True)
        if u.id == self.principal.user_id:
            raise Conflict(
                "change your own password with POST /api/v1/auth/password (it asks for the "
                "current one)",
                code="self_reset",
            )
        if not self.principal.is_superuser:
            if u.is_superuser:
                raise Forbidden(
                    "a platform superuser's password is theirs to change", code="superuser"
                )
            others = [o for _, o in await UserRepository(self.db).memberships(u.id)]
            if any(o.id != m.organization_id for o in others):
                raise Forbidden(
                    f"{u.email} is a member of other organisations too: their password is theirs "
                    "to change, or a platform superuser's to reset",
                    code="other_organisations",
                )
        u.password_hash = await asyncio.to_thread(passwords.hash, new)
        ended = await SessionService(self.uow, self.settings).end_all_for_user(
            u.id, "password_reset"
        )
        await record(
            self.uow, self.principal, "user.password_reset", target=u.email, sessions=len(ended)
        )
        return len(ended)

    async def remove_user(self, user_id: uuid.UUID, expect: IfMatch = NO_PRECONDITION) -> None:
        """Remove a member from the caller's organisation and end their sessions there."""
        m, u = await self.user(user_id, lock=True)
        expect.check(m.version, f"user {u.id}")
        if u.id == self.principal.user_id:
            raise Conflict("you cannot remove yourself", code="self_removal")
        await SessionService(self.uow, self.settings).end_all_for_user(
            u.id, "removed", self.principal.organization_id
        )
        await self.db.delete(m)
        await record(self.uow, self.principal, "user.removed", target=u.email)
