"""Every public module, class, function and method of the library (and of the harness it
ships as ``wcdrive.hil``) has a docstring."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def undocumented(path: Path) -> list[str]:
    """``file:line name`` of each public definition in ``path`` without a docstring."""
    tree = ast.parse(path.read_text())
    where = path.relative_to(REPO)
    missing = [f"{where}:1 (module)"] if ast.get_docstring(tree) is None else []

    def visit(body: list[ast.stmt], prefix: str) -> None:
        for node in body:
            if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                continue
            if node.name.startswith("_"):
                continue
            decorators = {d.id if isinstance(d, ast.Name) else getattr(d, "attr", "")
                          for d in node.decorator_list}
            if "overload" in decorators:
                continue
            if any(isinstance(d, ast.Attribute) and d.attr in ("setter", "deleter")
                   for d in node.decorator_list):
                continue
            if ast.get_docstring(node) is None:
                missing.append(f"{where}:{node.lineno} {prefix}{node.name}")
            if isinstance(node, ast.ClassDef):
                visit(node.body, f"{prefix}{node.name}.")

    visit(tree.body, "")
    return missing


def _sources() -> list[Path]:
    return sorted([*(REPO / "wcdrive").rglob("*.py"), *(REPO / "hil").rglob("*.py")])


def test_public_api_has_docstrings() -> None:
    missing = [m for path in _sources() for m in undocumented(path)]
    assert missing == [], "\n".join(missing)


def test_the_check_sees_a_missing_docstring(tmp_path: Path) -> None:
    probe = REPO / "wcdrive" / "_probe_undocumented.py"
    probe.write_text('"""A module."""\n\n\ndef public() -> None:\n    pass\n\n\nclass Thing:\n'
                     '    """Documented."""\n\n    def method(self) -> None:\n        pass\n')
    try:
        got = undocumented(probe)
    finally:
        probe.unlink()
    assert [g.split(" ")[1] for g in got] == ["public", "Thing.method"]
