"""Decisions about organisations, users and roles (shared by the API and the admin CLI)."""

from __future__ import annotations

import asyncio
import uuid

from sqlalchemy.ext.asyncio import AsyncSession

from server.kit.errors import Conflict, NotFound
from server.kit.security import Passwords
from server.organizations.models import Membership, Organization, Role, User
from server.organizations.repository import OrganizationRepository, UserRepository


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
