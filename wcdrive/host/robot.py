"""``Robot``: the navigation surface every robot wcdrive drives has in common; beside it,
the protocols of the extras some robots have (``EstopSurface``, ``BoardHealthSurface``,
``LidarSurface``, ``NamedSurface``).

wcdrive drives two robots: the Mega wheelchair (``wcdrive.host.wheelchair.Wheelchair``)
and the Parallax Eddie (``wcdrive.eddie.robot.EddieRobot``). Navigation code written
against ``Robot`` runs on either unchanged (``wcdrive.connect("sim://")``,
``"simavr://"``, ``"eddie+sim://"``, ``"eddie:///dev/ttyUSB0"``). It is a structural
``typing.Protocol``, not a base class: the two classes share no code (one speaks
framed protocol v4 with acknowledgements, the other the Eddie's request/reply ASCII),
so a base class would hold nothing but these signatures. Each robot's kinematics
(``wheel_angles``) and limits (``command_limits``) are its own, so a ROS node or a
logger serves any robot without asking which it is.

Each robot's extras stay on its own class (the chair's e-stop, board reports, lidar
and parameters; Eddie's PING))), ADC, GPIO, ``travel``/``turn``): code that needs
them checks ``isinstance``, and mypy then types the call. Against the class, or, for
an extra that code serves on any robot that has it (the ROS node,
``wcdrive.ros2.dds.node``), against one of the runtime-checkable protocols below,
which ``Wheelchair`` (all but ``NamedSurface``) and ``EddieRobot`` (``NamedSurface``)
satisfy as they are, and a plugin's robot or a test's stand-in by having the same
members. docs/eddie.md says why not capability flags.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Protocol, Self, runtime_checkable

from wcdrive.host.odometry import OdometryEstimate
from wcdrive.host.telemetry import Telemetry
from wcdrive.protocol.codec import ExtendedTelemetry, LineStats

if TYPE_CHECKING:                     # the host side loads no simulator
    from wcdrive.plant.lidar import LaserScan, Lidar


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


@runtime_checkable
class EstopSurface(Protocol):
    """A robot with a latched e-stop (``Wheelchair``): ``estop()`` latches it and the
    robot refuses motion until ``reset_estop()``; ``estop_latched`` says whether it is."""

    def estop(self) -> None:
        """Latches the e-stop."""

    def reset_estop(self) -> None:
        """Releases the e-stop."""

    @property
    def estop_latched(self) -> bool:
        """Whether the e-stop is latched."""


@runtime_checkable
class BoardHealthSurface(Protocol):
    """A robot whose board reports its health (``Wheelchair``): where it is, what its
    lines came through as, the faults it latched and its last ``TLM:`` line."""

    @property
    def url(self) -> str:
        """The URL or device path of the board."""

    @property
    def link_stats(self) -> LineStats:
        """The board's lines so far: good, failed their check, spliced, lost."""

    @property
    def faults(self) -> tuple[str, ...]:
        """The faults the board has latched; empty when none."""

    @property
    def status(self) -> ExtendedTelemetry | None:
        """The board's last ``TLM:`` line, or None before the first."""


@runtime_checkable
class LidarSurface(Protocol):
    """A robot that may carry a lidar (``Wheelchair``): ``lidar`` (its model and mount)
    is None and ``has_lidar`` False without one; with one, ``on_scan`` hands on its scans."""

    @property
    def has_lidar(self) -> bool:
        """Whether the robot has a lidar whose scans reach the host."""

    @property
    def lidar(self) -> Lidar | None:
        """The lidar, or None."""

    def on_scan(self, callback: Callable[[LaserScan], None]) -> None:
        """Calls ``callback`` with every scan."""


@runtime_checkable
class NamedSurface(Protocol):
    """A robot that names itself (``EddieRobot``, a plugin's robot): ``name``, which a
    ROS node's diagnostics call it by when it has no board URL."""

    @property
    def name(self) -> str:
        """The robot's name."""
