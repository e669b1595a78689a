"""The layout rule of issue 12: no source file over 400 lines without a reason in its docstring."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("server", "base_station", "asset_agent", "assetlink", "protocol", "sim", "aerobase")
MAX_LINES = 400
REASON = "Long because:"


def too_long(path: Path) -> bool:
    """True when the file is over MAX_LINES lines and its module docstring gives no reason
    (a line starting with "Long because:")."""
    source = path.read_text()
    if len(source.splitlines()) <= MAX_LINES:
        return False
    doc = ast.get_docstring(ast.parse(source)) or ""
    return not any(line.strip().startswith(REASON) for line in doc.splitlines())


def offenders(root: Path = ROOT) -> list[str]:
    """Every over-long file without a stated reason, relative to `root`, with its line count."""
    out = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            name = path.relative_to(root).as_posix()
            if too_long(path):
                out.append(f"{name} ({len(path.read_text().splitlines())} lines)")
    return out


def test_no_source_file_is_over_400_lines_without_a_stated_reason() -> None:
    assert offenders() == [], (
        f"split these, or say why they must stay long in a docstring line starting {REASON!r}"
    )


def test_the_rule_catches_a_long_file_and_accepts_a_stated_reason(tmp_path: Path) -> None:
    package = tmp_path / "sim"
    package.mkdir()
    body = "x = 1\n" * MAX_LINES
    (package / "short.py").write_text('"""Short."""\n' + "x = 1\n" * (MAX_LINES - 1))
    (package / "long.py").write_text('"""Long, and silent about it."""\n' + body)
    (package / "reasoned.py").write_text(
        '"""A generated table.\n\nLong because: one row per register.\n"""\n' + body
    )
    assert offenders(tmp_path) == [f"sim/long.py ({MAX_LINES + 1} lines)"]
