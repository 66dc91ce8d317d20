"""The navigation helpers live in ``wcdrive.navigation``; their old names under
``wcdrive.sim`` still give the same objects for one release, with a warning."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from wcdrive.navigation import ekf, icp, pure_pursuit


@pytest.mark.parametrize(("old", "new", "name"), [
    ("wcdrive.sim.localization", ekf, "Ekf2D"),
    ("wcdrive.sim.icp", icp, "icp"),
    ("wcdrive.sim.navigation", pure_pursuit, "PurePursuit"),
])
def test_the_old_name_warns_and_gives_the_same_object(old: str, new: object, name: str) -> None:
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match="wcdrive.navigation"):
        module = importlib.import_module(old)
    assert getattr(module, name) is getattr(new, name)


def test_the_library_itself_uses_the_new_names() -> None:
    """A fresh interpreter loading the runner, the reports and the CLI loads none of the
    old modules (which would warn every user)."""
    code = ("import sys, wcdrive.sim.runner, wcdrive.sim.report, wcdrive.sim.compare, wcdrive.tools.cli\n"
            "print(sorted(m for m in sys.modules if m in ('wcdrive.sim.localization', "
            "'wcdrive.sim.icp', 'wcdrive.sim.navigation')))")
    out = subprocess.run([sys.executable, "-W", "error:wcdrive.sim:DeprecationWarning", "-c", code],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"
