"""The example downstream project (tests/downstream/) passes in a fresh virtual
environment where wcdrive is installed from the checkout with ``pip install``, using
only the pytest plugin (entry point, no conftest) and ``wcdrive.testing.strategies``.

For speed the venv sees the system's site-packages (numpy, pymunk, pytest, hypothesis:
wcdrive's dependencies, installed by scripts/test.sh) and wcdrive is installed without
them (``--no-deps``); the test checks that the wcdrive it imports is the venv's own
copy, not the checkout's."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

from tests.support.checkout import checkout_copy

REPO = Path(__file__).resolve().parents[2]


def test_downstream_project_passes_in_a_fresh_venv(tmp_path: Path) -> None:
    env_dir = tmp_path / "venv"
    venv.create(env_dir, system_site_packages=True, with_pip=False)
    python = env_dir / "bin" / "python"
    source = checkout_copy(tmp_path / "wcdrive-src")
    # the outer run's settings (xdist's PYTEST_XDIST_WORKER, PYTEST_ADDOPTS ...) stay out
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH" and not k.startswith("PYTEST_")}
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps",
         "--disable-pip-version-check", str(source)],
        capture_output=True, text=True, env=env, timeout=600)
    assert install.returncode == 0, install.stdout + install.stderr
    where = subprocess.run([str(python), "-c", "import wcdrive.testing, sys; print(wcdrive.__file__)"],
                           capture_output=True, text=True, env=env, cwd=tmp_path)
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(env_dir), where.stdout

    project = shutil.copytree(REPO / "tests" / "downstream", tmp_path / "downstream")
    assert not (project / "conftest.py").exists() and not (project / "tests" / "conftest.py").exists()
    run = subprocess.run([str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                          "-W", "error::pytest.PytestWarning", "-o", "addopts="],
                         cwd=project, capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert " passed" in run.stdout and "failed" not in run.stdout and "skipped" not in run.stdout
