"""A copy of the checkout for tests that build or install wcdrive from source, so that
the build (setuptools' ``build/`` and ``*.egg-info``) writes nothing into the checkout
another test worker may be building from at the same time."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def checkout_copy(dest: Path) -> Path:
    """The checkout's files (tracked and new, not ignored) in ``dest``."""
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                            cwd=REPO, capture_output=True, text=True)
    if listed.returncode != 0:
        pytest.skip("not a git checkout")
    for name in listed.stdout.splitlines():
        src = REPO / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return dest
