"""`protocol` holds wire models only: every import in it is the standard library, pydantic or
`protocol` itself (STYLE.md: "protocol/ depends on pydantic only")."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ALLOWED = {"pydantic", "protocol"}


def imported_roots(path: Path) -> set[str]:
    """Top-level names of the modules a file imports (absolute imports only)."""
    roots: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


def test_protocol_imports_only_pydantic_and_the_standard_library() -> None:
    """Any other package (httpx, websockets, cryptography, our deployables) is a finding."""
    findings = {
        str(path.relative_to(ROOT)): sorted(bad)
        for path in sorted((ROOT / "protocol").rglob("*.py"))
        if (bad := imported_roots(path) - ALLOWED - set(sys.stdlib_module_names) - {"__future__"})
    }
    assert findings == {}


def test_the_check_sees_a_third_party_import(tmp_path: Path) -> None:
    """The scan itself finds a forbidden import, including one inside a function."""
    sample = tmp_path / "sample.py"
    sample.write_text("import json\n\ndef f():\n    from httpx import get\n    return get\n")
    assert imported_roots(sample) - set(sys.stdlib_module_names) == {"httpx"}
