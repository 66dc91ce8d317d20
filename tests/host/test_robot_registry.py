"""Robots besides the chair are plugins (``wcdrive.host.robots``): found through the
``wcdrive.robots`` entry-point group, their pyserial handlers through
``wcdrive.serial_urls``. The Eddie is one; a third robot is one package plus one entry
point (``tests/support/tinybot``, installed here as a ``.dist-info`` on ``sys.path``)."""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

import wcdrive
from wcdrive.errors import WcdriveError
from wcdrive.host import robots
from wcdrive.host.robot import Robot

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tinybot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """tests/support/tinybot registered as an installed distribution would be."""
    dist = tmp_path / "tinybot-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: tinybot\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text('[wcdrive.robots]\ntinybot = tests.support.tinybot:ROBOT\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path


def test_the_eddie_is_a_plugin() -> None:
    entry = robots.registered()["eddie"]
    assert entry.prefixes == ("eddie+sim://", "eddie://")
    assert robots.entry_for("eddie+sim://?speed=5") is entry
    assert robots.entry_for("sim://") is None and robots.entry_for("/dev/ttyACM0") is None
    assert wcdrive.EddieRobot is robots.extra("eddie", "robot_class")


def test_a_new_robot_is_one_package_and_one_entry_point(tinybot: Path) -> None:
    from tests.support.tinybot import TinyBot

    with wcdrive.connect("tiny://anything") as bot:
        assert isinstance(bot, Robot) and isinstance(bot, TinyBot)
        bot.set_velocity(0.5, 0.25)
        assert bot.command_limits == (1.0, 2.0)
    assert bot.commands[-1] == (0.0, 0.0)               # leaving the block stopped it


def test_two_plugins_claiming_a_prefix_is_an_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    dist = tmp_path / "clash-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: clash\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[wcdrive.robots]\nclash = tests.support.tinybot:CLASH\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import tests.support.tinybot as tiny

    clash = robots.RobotEntry("clash", ("eddie://",), tiny._connect)
    monkeypatch.setattr(tiny, "CLASH", clash, raising=False)
    with pytest.raises(WcdriveError, match=r"'(eddie|clash)' and '(eddie|clash)' both claim 'eddie://'"):
        robots.registered()


def test_an_unknown_robot_or_extra_names_what_is_there() -> None:
    with pytest.raises(WcdriveError, match=r"installed: .*eddie"):
        robots.extra("nobot", "runner")
    with pytest.raises(WcdriveError, match=r"offers: .*runner"):
        robots.extra("eddie", "nothing")


def test_every_wc_scheme_reaches_pyserial_through_the_entry_points() -> None:
    """A fresh interpreter, wcdrive not imported: pyserial finds wcsim and wceddie."""
    code = ("import serial, sys\n"
            "for url in ('wcsim://?speed=5', 'wceddie://?speed=5'):\n"
            "    p = serial.serial_for_url(url, timeout=0.1); p.close()\n"
            "print(sorted(m for m in sys.modules if m.startswith('wcdrive.eddie')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd="/")
    assert out.returncode == 0, out.stderr
    assert "wcdrive.eddie.serial_url" in out.stdout


def test_nothing_outside_the_eddie_package_imports_it() -> None:
    files = subprocess.run(["git", "ls-files", "wcdrive"], cwd=REPO, capture_output=True, text=True,
                           check=True).stdout.split()
    pattern = re.compile(r"^\s*(from wcdrive\.eddie\b|import wcdrive\.eddie\b|from wcdrive import eddie\b)")
    found = [f"{p}:{n}" for p in files if p.endswith(".py") and not p.startswith("wcdrive/eddie/")
             for n, line in enumerate((REPO / p).read_text().splitlines(), 1) if pattern.search(line)]
    assert not found, found


def test_the_old_handler_name_warns_and_is_the_plugins() -> None:
    import importlib

    sys.modules.pop("wcdrive.transports.urlhandler.protocol_wceddie", None)
    with pytest.warns(DeprecationWarning, match="wcdrive.eddie.serial_url"):
        old = importlib.import_module("wcdrive.transports.urlhandler.protocol_wceddie")
    assert old.Serial.__module__ == "wcdrive.eddie.serial_url"
