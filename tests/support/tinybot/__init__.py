"""A tiny third robot, to show that a robot is one package plus one entry point
(``tests/host/test_robot_registry.py`` installs it by putting a ``.dist-info`` with its
entry points on ``sys.path``). It drives nothing: its "link" is a ``loop://`` port,
and it keeps the last command it was given."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, Self

from wcdrive.host.odometry import OdometryEstimate, OdometryParams, WheelOdometry
from wcdrive.host.robots import Link, RobotEntry
from wcdrive.host.telemetry import Telemetry


class TinyBot:
    """The ``Robot`` surface, and nothing behind it but a port it writes to."""

    def __init__(self, port: Any, name: str) -> None:
        self.port, self.name = port, name
        self.commands: list[tuple[float, float]] = []
        self._odometry = WheelOdometry(OdometryParams(wheel_radius=0.05, wheelbase=0.2, counts_per_rev=100),
                                       "position")

    def set_velocity(self, linear: float, angular: float) -> None:
        self.commands.append((linear, angular))
        self.port.write(f"v {linear} {angular}\n".encode())

    def stop(self) -> None:
        self.set_velocity(0.0, 0.0)

    @property
    def odometry(self) -> OdometryEstimate:
        return self._odometry.estimate(0.0)

    def telemetry(self, timeout: float | None = None) -> Iterator[Telemetry]:
        return iter(())

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        pass

    @property
    def link_ok(self) -> bool:
        return True

    def close(self) -> None:
        self.stop()
        self.port.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def wheel_angles(self, sample: Telemetry) -> tuple[float, float]:
        return sample.count_left * 0.01, sample.count_right * 0.01

    @property
    def command_limits(self) -> tuple[float, float]:
        return 1.0, 2.0


def _connect(url: str, link: Link, **options: Any) -> TinyBot:
    options.pop("boot_timeout", None)
    return TinyBot(link.wrap(link.open_url("loop://")), name=url)


ROBOT = RobotEntry("tinybot", ("tiny://",), _connect, description="a test robot")
