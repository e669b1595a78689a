"""Code conventions a reviewer would otherwise have to remember."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _unmarked_selects(path: Path) -> list[str]:
    """Calls of a bare `select(...)` whose statement carries no `# unscoped: <why>` comment.

    The comment may sit anywhere in the statement or on the line above it, so a formatter that
    wraps the statement does not move it out of reach."""
    source = path.read_text()
    lines = source.splitlines()
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    out = []
    for node in ast.walk(tree):
        if not (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "select"
        ):
            continue
        stmt: ast.AST = node
        while not isinstance(stmt, ast.stmt):
            stmt = parents[stmt]
        first = stmt.lineno
        last = stmt.end_lineno or stmt.lineno
        body = getattr(stmt, "body", None)
        if isinstance(body, list) and body:  # a compound statement: its header only
            last = min(last, body[0].lineno - 1)
        span = lines[max(first - 2, 0) : last]
        if not any("# unscoped:" in line for line in span):
            name = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name
            out.append(f"{name}:{node.lineno}: {lines[node.lineno - 1].strip()}")
    return out


def test_every_raw_select_in_a_repository_says_why_it_is_unscoped():
    """Organisation scoping happens in one place: `ScopedRepository.select()` / `scoped()`."""
    offenders = []
    for path in (ROOT / "server").rglob("*.py"):
        if path.name == "repository.py" or "repositories" in path.parts:
            offenders += _unmarked_selects(path)
    assert not offenders, "raw select() without '# unscoped: <why>':\n" + "\n".join(offenders)


def test_endpoints_do_not_write_sql():
    """SQL lives in repositories; endpoints call services and repositories."""
    offenders = []
    for path in (ROOT / "server").rglob("endpoints.py"):
        offenders += _unmarked_selects(path)
    assert not offenders, offenders


def test_the_convention_check_sees_an_unmarked_select(tmp_path):
    """The check itself: a wrapped, unmarked select is caught; a marked one is not."""
    probe = tmp_path / "repository.py"
    probe.write_text(
        "stmt = (\n    select(A).where(A.x == 1)\n)\n"
        "# unscoped: marked above\nok = select(B)\n"
        "also = (\n    select(C).where(C.y == 2)\n)  # unscoped: marked after the wrap\n"
    )
    found = _unmarked_selects(probe)
    assert [f.split(":")[1] for f in found] == ["2"], found


def test_frontend_api_documents_every_openapi_path(api):
    doc = (ROOT / "frontend_api.md").read_text()
    spec = api.get("/api/openapi.json").json()
    missing = []
    for path, item in spec["paths"].items():
        for method in item:
            if f"{method.upper()} {path}" not in doc:
                missing.append(f"{method.upper()} {path}")
    assert not missing, "frontend_api.md lacks: " + ", ".join(missing)


def _long_functions(path: Path, limit: int) -> list[str]:
    """Functions (and methods) of a module longer than `limit` lines, decorators excluded."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            length = (node.end_lineno or node.lineno) - node.lineno + 1
            if length > limit:
                out.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.name} ({length} lines)")
    return out


def test_no_function_in_the_run_package_is_over_80_lines():
    """The run machine is a table and a short evaluator; the engine a few small steps."""
    offenders = []
    for path in (ROOT / "server" / "runs").rglob("*.py"):
        offenders += _long_functions(path, 80)
    assert not offenders, offenders


def test_the_length_check_sees_a_long_function():
    probe = ROOT / "server" / "runs" / "machine.py"
    assert _long_functions(probe, 5)  # the same file has functions longer than 5 lines


def _commits(path: Path) -> list[str]:
    """Calls of `.commit(` in a module (a unit of work is committed at the boundary only)."""
    tree = ast.parse(path.read_text())
    return [
        f"{path.relative_to(ROOT)}:{node.lineno}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Attribute)
        and node.func.attr == "commit"
    ]


def test_no_endpoint_module_commits():
    """One unit of work per request: the request's dependency commits once, endpoints never do."""
    offenders = []
    for path in (ROOT / "server").rglob("endpoints.py"):
        offenders += _commits(path)
    assert not offenders, "endpoint modules calling commit():\n" + "\n".join(offenders)


def test_the_commit_check_sees_a_commit(tmp_path):
    probe = tmp_path / "endpoints.py"
    probe.write_text("async def f(db):\n    await db.commit()\n")
    tree = ast.parse(probe.read_text())
    assert any(
        isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "commit"
        for n in ast.walk(tree)
    )
