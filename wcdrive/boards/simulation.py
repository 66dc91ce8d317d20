"""``Simulated``: what a simulated board offers the floors above it, typed, with the
board's lock kept inside: its clock and pacing, its lidar, its gyro's samples and the
plant's ground truth.

    sim = simulation_of(port)          # wcdrive.transports.port: None for a device
    if sim is not None:
        truth = sim.ground_truth()     # GroundTruth(time, x, y, heading, linear, angular)
        samples = sim.gyro_samples(0)  # every sample the gyro still keeps

Every simulated board (``ThreadedBoard``: ``SimulatedBoard``, ``MegaBoard``, the Eddie's
board) is one. The host, the ROS 2 bridge and the API reach the simulation through
this interface only, never through a board's attributes: a reading is taken between
two steps of the board's thread, under its lock, so it is of one simulated instant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from wcdrive.boards.board_lidar import BoardLidar

__all__ = ["GroundTruth", "GyroSamples", "Simulated"]


@dataclass(frozen=True, slots=True)
class GroundTruth:
    """The simulated chair at one instant: ``time`` (simulated s since boot), its pose
    (x, y in m, heading in rad), the axle's ``linear`` speed (m/s) and the yaw rate
    ``angular`` (rad/s)."""

    time: float
    x: float
    y: float
    heading: float
    linear: float
    angular: float


@dataclass(frozen=True, slots=True)
class GyroSamples:
    """The gyro's samples after the first ``seen`` it ever took: ``samples`` as (time s,
    rate rad/s), oldest first (those it still keeps: a live board keeps the newest
    only), and ``total``, how many it has taken (the next call's ``seen``)."""

    samples: tuple[tuple[float, float], ...]
    total: int


@runtime_checkable
class Simulated(Protocol):
    """A simulated board, as the floors above see it."""

    @property
    def reported_time(self) -> float | None:
        """How far the board's output has come on its own clock (s); None when its thread
        does not run (``ThreadedBoard.reported_time``)."""

    @property
    def speed(self) -> float:
        """Simulated seconds per wall-clock second."""

    @property
    def lidar(self) -> BoardLidar | None:
        """The lidar on the board's chair, if it has one."""

    @property
    def gyro_noise_dps(self) -> float:
        """The gyro's rate noise (deg/s rms); 0 without a gyro."""

    def ground_truth(self) -> GroundTruth | None:
        """The plant now; None for a board without one."""

    def gyro_samples(self, seen: int) -> GyroSamples:
        """The gyro's samples after the first ``seen``."""
