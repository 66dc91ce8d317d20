"""The Parallax Eddie as a ``wcdrive.connect`` robot: the ``RobotEntry`` that the
``wcdrive.robots`` entry point ``eddie`` names (``wcdrive.host.robots``).

    eddie+sim://[?speed=S&seed=N&eol=firmware|tolerant]   a simulated Eddie (wceddie://)
    eddie:///dev/ttyUSB0                                   a real one

Both give an ``EddieRobot`` (docs/eddie.md), which has the navigation surface of
``wcdrive.host.robot.Robot``.
"""

from __future__ import annotations

from typing import Any

from wcdrive.eddie.robot import EddieRobot
from wcdrive.errors import WcdriveConnectionError
from wcdrive.host.robots import Link, RobotEntry

__all__ = ["ROBOT"]


def _connect(url: str, link: Link, **options: Any) -> EddieRobot:
    """``eddie+sim://...`` (``wceddie://...``) or ``eddie://<device path>``; ``options``
    go to ``EddieRobot`` (``boot_timeout``: how long to ask ``VER`` before giving up)."""
    if url.startswith("eddie+sim://"):
        port = link.open_url("wceddie://" + url[len("eddie+sim://"):])
    else:
        path = url[len("eddie://"):]
        if not path.startswith("/"):
            raise WcdriveConnectionError(f"unsupported URL {url!r}: use eddie:///dev/ttyUSB0")
        port = link.open_device(path)
    options.setdefault("name", url)
    try:
        return EddieRobot(link.wrap(port), **options)
    except BaseException:
        port.close()
        raise


ROBOT = RobotEntry("eddie", ("eddie+sim://", "eddie://"), _connect,
                   description="the Parallax Eddie (docs/eddie.md)",
                   extras={"robot_class": EddieRobot, "runner": "wcdrive.eddie.runner",
                           "sim_board": "wcdrive.eddie.board:EddieSimBoard"})
