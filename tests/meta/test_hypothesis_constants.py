"""A derandomized test draws the same examples whatever its process imported before
it: hypothesis' pool of the project's constants is held from the start
(tests/support/hypothesis_constants.py). Without the hold, a module imported between
two runs of the same test (here one this test writes, full of new literals; in a
pytest-xdist worker whatever the tests before it imported) changed the examples."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from hypothesis import Phase, given, settings
from hypothesis import strategies as st

from tests.support.hypothesis_constants import NOT_IMPORTED, project_modules

_LITERALS = '''
"""Literals hypothesis would add to its pool: a module of the project's kind."""
FLOATS = (1234.5678, 0.000271828, 98765.4321, 3.14159e-7, 271.828182, 61.25)
INTEGERS = (987654321, 31337, 4242424, 65521, 1000003, 8191)
TEXTS = ("zq-probe", "wcdrive-constant", "held pool", "xyzzy", "plugh", "thirteen")
'''


def _draws() -> list[tuple[float, int, str]]:
    seen: list[tuple[float, int, str]] = []

    @settings(derandomize=True, database=None, max_examples=300, phases=[Phase.generate],
              deadline=None)
    @given(st.floats(allow_nan=False), st.integers(), st.text(max_size=12))
    def probe(x: float, n: int, s: str) -> None:
        seen.append((x, n, s))

    probe()
    return seen


def test_a_module_imported_between_two_runs_does_not_change_the_examples(tmp_path: Path) -> None:
    before = _draws()
    path = tmp_path / "wc_probe_literals.py"
    path.write_text(_LITERALS)
    spec = importlib.util.spec_from_file_location("wc_probe_literals", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["wc_probe_literals"] = module
    try:
        spec.loader.exec_module(module)
        after = _draws()
    finally:
        del sys.modules["wc_probe_literals"]
    assert len(before) == len(after) == 300
    assert before == after


def test_every_library_module_was_imported_before_the_first_test() -> None:
    """The pool was taken with the whole library imported (pkgutil's walk, less the
    modules that are not Python)."""
    missing = [name for name in project_modules() if name not in sys.modules and name not in NOT_IMPORTED]
    assert not missing
