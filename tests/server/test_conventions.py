"""Code conventions a reviewer would otherwise have to remember."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_raw_select_in_a_repository_says_why_it_is_unscoped():
    """Organisation scoping happens in one place: `ScopedRepository.select()` / `scoped()`."""
    offenders = []
    for path in (ROOT / "server").rglob("*.py"):
        if path.name != "repository.py" and "repositories" not in path.parts:
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if (
                re.search(r"\bselect\(", line)
                and "self.select()" not in line
                and "# unscoped:" not in line
            ):
                offenders.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not offenders, "raw select() without '# unscoped: <why>':\n" + "\n".join(offenders)


def test_endpoints_do_not_write_sql():
    """SQL lives in repositories; endpoints call services and repositories."""
    offenders = []
    for path in (ROOT / "server").rglob("endpoints.py"):
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"\bselect\(", line) and "# unscoped:" not in line:
                offenders.append(f"{path.relative_to(ROOT)}:{n}")
    assert not offenders, offenders


def test_frontend_api_documents_every_openapi_path(api):
    doc = (ROOT / "frontend_api.md").read_text()
    spec = api.get("/api/openapi.json").json()
    missing = []
    for path, item in spec["paths"].items():
        for method in item:
            if f"{method.upper()} {path}" not in doc:
                missing.append(f"{method.upper()} {path}")
    assert not missing, "frontend_api.md lacks: " + ", ".join(missing)
