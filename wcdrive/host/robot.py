"""``Robot``: the navigation surface every robot wcdrive drives has in common.

wcdrive drives two robots: the Mega wheelchair (``wcdrive.host.wheelchair.Wheelchair``)
and the Parallax Eddie (``wcdrive.eddie.robot.EddieRobot``). Navigation code written
against ``Robot`` runs on either unchanged (``wcdrive.connect("sim://")``,
``"simavr://"``, ``"eddie+sim://"``, ``"eddie:///dev/ttyUSB0"``). It is a structural
``typing.Protocol``, not a base class: the two classes share no code (one speaks
framed protocol v4 with acknowledgements, the other the Eddie's request/reply ASCII),
so a base class would hold nothing but these signatures. Each robot's kinematics
(``wheel_angles``) and limits (``command_limits``) are its own, so a ROS node or a
logger serves any robot without asking which it is. Each robot's extras stay on its own class (the chair's
e-stop and parameters; Eddie's PING))), ADC, GPIO, ``travel``/``turn``): code that
needs them checks ``isinstance``. docs/eddie.md says why not capability flags.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Protocol, Self, runtime_checkable

from wcdrive.host.odometry import OdometryEstimate
from wcdrive.host.telemetry import Telemetry


@runtime_checkable
class Robot(Protocol):
    """The common navigation surface (module docstring)."""

    def set_velocity(self, linear: float, angular: float) -> None:
        """Drive at ``linear`` m/s and ``angular`` rad/s; send again at >= 2 Hz."""

    def stop(self) -> None:
        """Stop the robot."""

    @property
    def odometry(self) -> OdometryEstimate:
        """The latest pose, speeds and covariances."""

    def telemetry(self, timeout: float | None = None) -> Iterator[Telemetry]:
        """Each sample of wheel positions and speeds as it arrives."""

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        """Calls ``callback`` with each sample."""

    @property
    def link_ok(self) -> bool:
        """Whether the board answers."""

    def close(self) -> None:
        """Stops the robot and closes the link."""

    def __enter__(self) -> Self:
        """The robot, in a ``with`` block that stops it and closes the link on leaving."""

    def __exit__(self, *exc: object) -> None:
        """``close``."""

    def wheel_angles(self, sample: Telemetry) -> tuple[float, float]:
        """The wheels' angles (rad, forward positive; left, right) at ``sample``: the
        robot's own encoder kinematics."""

    @property
    def command_limits(self) -> tuple[float, float]:
        """The largest ``|linear|`` (m/s) and ``|angular|`` (rad/s) ``set_velocity``
        takes."""
