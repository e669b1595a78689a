"""The server's long-lived services reach their users as one typed object, never through `app.state`."""

from __future__ import annotations

import dataclasses
import re
import typing
from pathlib import Path

import pytest

from server.services import Services

ROOT = Path(__file__).resolve().parents[2] / "server"
UNTYPED = re.compile(r"\bapp\.state\b|\bstate: Any\b")


def test_only_deps_touches_app_state() -> None:
    """`server.deps` hands the services over; everyone else takes `Services` (a route: ServicesDep)."""
    offenders = [
        f"{path.relative_to(ROOT.parent)}:{n}"
        for path in ROOT.rglob("*.py")
        if path != ROOT / "deps.py"
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if UNTYPED.search(line)
        and not line.lstrip().startswith(("#", '"'))
        and "`app.state`" not in line
    ]
    assert offenders == []


def test_services_are_frozen_and_typed() -> None:
    assert dataclasses.is_dataclass(Services)
    hints = typing.get_type_hints(Services)
    assert hints and all(hint is not typing.Any for hint in hints.values())
    fields = {f.name for f in dataclasses.fields(Services)}
    assert {"settings", "sessionmaker", "broker", "hub", "ingest", "telemetry"} <= fields
    services = Services.__new__(Services)
    with pytest.raises(dataclasses.FrozenInstanceError):
        services.settings = None  # type: ignore[misc,assignment]
