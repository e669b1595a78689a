"""What a base command yields while it runs (`Progress`) and how it ends (`Result`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any


class Status(StrEnum):
    """How a command ended."""

    SUCCEEDED = "succeeded"
    REJECTED = "rejected"
    FAILED = "failed"


@dataclass(frozen=True)
class Progress:
    """One progress step of a running command."""

    command: str
    step: str
    message: str
    percent: float | None = None


@dataclass(frozen=True)
class Result:
    """The end of a command."""

    command: str
    status: Status
    reason: str
    data: dict[str, Any] = field(default_factory=dict)


Item = Progress | Result
