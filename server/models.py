"""Imports every table so that metadata (and Alembic autogenerate) sees them all."""

from server.airspace.models import AirspaceZone
from server.assets.models import Asset, AssetKind
from server.audit.models import AuditEvent
from server.auth.models import AuthSession, LoginFailure
from server.commands.models import AssetCommand, CommandStatusChange
from server.kit.db import Base
from server.kit.principal import Role
from server.missions.models import Mission, MissionKind
from server.organizations.models import Membership, Organization, User
from server.runs.models import Run, RunStepCommand, RunTransition
from server.schedules.models import Schedule
from server.telemetry.models import AssetEvent, AssetStream, TelemetrySample

__all__ = [
    "AirspaceZone",
    "Asset",
    "AssetCommand",
    "AssetEvent",
    "AssetKind",
    "AssetStream",
    "AuditEvent",
    "AuthSession",
    "Base",
    "CommandStatusChange",
    "LoginFailure",
    "Membership",
    "Mission",
    "MissionKind",
    "Organization",
    "Role",
    "Run",
    "RunStepCommand",
    "RunTransition",
    "Schedule",
    "TelemetrySample",
    "User",
]
