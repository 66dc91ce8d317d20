"""The documentation site (mkdocs.yml) builds with warnings as errors, and every fenced
code block of its pages runs: ``python`` blocks (or, with ``title="name"``, written to
that file), ``toml`` blocks with a title written as files, and ``sh`` blocks run by
bash in the page's own scratch folder, in page order. Indented blocks are transcripts
of what needs a board, a cluster or ROS (the pages say so)."""

from __future__ import annotations

import os
import py_compile
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
#: The pages whose blocks run (README.md's are tests/meta/test_docs.py's; architecture,
#: safety, avr-arithmetic and benchmarks have no fenced blocks; PROTOCOL.md's are wire
#: transcripts).
PAGES = ["docs/getting-started.md", "docs/testing.md", "docs/sweeps.md", "docs/logging.md",
         "docs/bench.md", "docs/ros2.md", "protocol/CAN.md", "docs/eddie.md", "docs/odometry.md",
         "docs/lidar.md"]
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```\s*$", re.S | re.M)


def blocks(page: str) -> list[tuple[str, str | None, str]]:
    """(language, title or None, code) of every fenced block of ``page``."""
    out = []
    for lang, info, code in FENCE.findall((REPO / page).read_text()):
        title = re.search(r'title="([^"]+)"', info)
        out.append((lang, title[1] if title else None, code))
    return out


def test_site_builds_with_warnings_as_errors(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                             str(tmp_path / "site")], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    site = tmp_path / "site"
    for page in ("index.html", "docs/getting-started/index.html", "docs/api/index.html",
                 "protocol/CAN/index.html", "protocol/PROTOCOL/index.html", "docs/architecture/index.html",
                 "docs/safety/index.html", "firmware/final_control/index.html"):
        assert (site / page).exists(), page
    api = (site / "docs/api/index.html").read_text()
    for name in ("wcdrive.api.connect", "SteppedChair", "history_limit", "byte_streams", "load_spec"):
        assert name in api, name


def test_every_page_in_the_nav_is_checked() -> None:
    nav = re.findall(r":\s+(\S+\.md)$", (REPO / "mkdocs.yml").read_text(), re.M)
    unchecked = set(nav) - set(PAGES) - {"index.md", "docs/architecture.md", "docs/safety.md",
                                         "docs/benchmarks.md", "docs/api.md", "protocol/PROTOCOL.md",
                                         "firmware/final_control/README.md", "docs/changelog.md",
                                         "docs/avr-arithmetic.md"}
    assert not unchecked, unchecked
    for page in ("docs/architecture.md", "docs/safety.md", "docs/benchmarks.md", "docs/api.md",
                 "docs/changelog.md", "docs/avr-arithmetic.md"):
        assert not blocks(page), page


def test_every_changelog_entry_names_a_test_that_exists() -> None:
    """Each entry of docs/changelog.md ends naming the test that holds it."""
    entries = re.split(r"^- ", (REPO / "docs/changelog.md").read_text(), flags=re.M)[1:]
    assert entries
    for entry in entries:
        named = re.findall(r"`(tests/[\w/]+\.py)`", entry)
        assert named, entry
        for path in named:
            assert (REPO / path).is_file(), path


@pytest.mark.parametrize("page", PAGES)
def test_code_blocks_run(page: str, tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}   # not xdist's
    env.update(PYTHONPATH=str(REPO), PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    ran = 0
    for lang, title, code in blocks(page):
        if title:
            (tmp_path / title).write_text(code)
            continue
        if lang == "python":
            cmd = [sys.executable, "-c", code]
        elif lang == "sh":
            cmd = ["bash", "-e", "-o", "pipefail", "-c", code.replace("python3 ", f"{sys.executable} ")]
        else:
            raise AssertionError(f"{page}: a {lang} block with no title: give it title=\"file\"")
        result = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=240)
        assert result.returncode == 0, f"{page}:\n{code}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
        ran += 1
    if page != "docs/ros2.md":
        assert ran, f"{page} has no block that runs"


def test_the_ros2_example_compiles() -> None:
    py_compile.compile(str(REPO / "examples" / "ros2_bridge.py"), doraise=True)
