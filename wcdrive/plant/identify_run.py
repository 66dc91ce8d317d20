"""What plant identification is fitted to: a ``Run``, one recorded experiment (the
ticks' board times, the signed duty each tick wrote, the wheels' angles at each tick,
on blocks or on the floor), with the intervals the fit compares (``Run.weights``) and
the duty schedule that drives its re-simulation (``Run.schedule``); and ``degraded``,
a run as a poorer recording would give it.

A recording may lose a tick's lines: the interval is then a gap (``GAP``), its duty
guessed, and the fit leaves it and the ``GAP_SETTLE`` s after it out, while the
simulation's state settles from the guess; a run with many gaps keeps little, and its
figures come out not pinned down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wcdrive.plant.params import ChairParams

__all__ = ["GAP", "GAP_SETTLE", "Run", "degraded"]

#: An interval longer than this many ticks is a gap: a tick's lines were lost.
GAP = 1.5
#: s after a gap that the fit leaves out, on blocks and on the floor: the wheel in the air
#: settles within a few of its 30 ms time constants; on the floor a guessed duty's error
#: lingered in the body's motion (0.5 and 1 s left rolling resistance 8 and 5 % off
#: with 5 % of the lines lost, benchmarks/identify.py).
GAP_SETTLE = {True: 0.2, False: 2.0}


@dataclass(frozen=True)
class Run:
    """One recorded experiment: ``millis`` (n) the ticks' board times in ms; ``duty``
    (n x 2, left and right) the signed duty (-255..255, + forward) each tick wrote,
    driving until the next; ``angle`` (n x 2) the wheels' angles at each tick (rad,
    forward +, from the encoder counts); ``blocks`` whether the wheels were off the
    ground. The first tick is at rest."""

    millis: np.ndarray
    duty: np.ndarray
    angle: np.ndarray
    blocks: bool
    name: str = ""
    #: (n-1) bools: the intervals over which a tick's lines were lost (its duty unknown);
    #: None: every interval longer than ``GAP`` ticks (a tick that ran late is one too).
    lost: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.millis)
        if n < 3 or self.duty.shape != (n, 2) or self.angle.shape != (n, 2):
            raise ValueError("a run needs 3 or more ticks, with a duty and an angle pair for each")
        if np.any(np.diff(self.millis) <= 0):
            raise ValueError("the ticks' millis must increase")

    @property
    def duration(self) -> float:
        """s from the first tick to the last."""
        return float(self.millis[-1] - self.millis[0]) / 1000.0

    @property
    def tick_ms(self) -> float:
        """ms of a control tick: the median interval."""
        return float(np.median(np.diff(self.millis)))

    def gaps(self) -> np.ndarray:
        """(n-1) bools: the intervals where a tick's lines were lost (its duty is not
        known): ``lost``, else those longer than ``GAP`` ticks."""
        if self.lost is not None:
            return self.lost
        return np.diff(self.millis) > GAP * self.tick_ms

    def weights(self) -> np.ndarray:
        """(n-1): 1 for an interval the fit compares, 0 for a gap and the ``GAP_SETTLE``
        s after it (the simulation guessed the lost duty: its state settles again). A
        run with many gaps keeps little: its figures come out not pinned down."""
        out = np.ones(len(self.millis) - 1)
        settle = math.ceil(GAP_SETTLE[self.blocks] * 1000.0 / self.tick_ms)
        for i in np.flatnonzero(self.gaps()):
            out[i:i + 1 + settle] = 0.0
        return out

    def schedule(self) -> list[tuple[int, float, float, int]]:
        """What drives the simulation: (steps, duty left, duty right, interval) runs of
        ``DT`` steps, each ending where the interval ``interval`` ends (-1: it does not).
        Over a gap the tick's own duty holds for a tick, then the mean of it and the
        next known one (the lost tick's, guessed)."""
        out: list[tuple[int, float, float, int]] = []
        gaps = self.gaps()
        tick = round(self.tick_ms)
        for i, n in enumerate(np.diff(self.millis).astype(int)):
            dl, dr = float(self.duty[i, 0]), float(self.duty[i, 1])
            if gaps[i]:
                out.append((tick, dl, dr, -1))
                out.append((int(n) - tick, round(0.5 * (dl + self.duty[i + 1, 0])),
                            round(0.5 * (dr + self.duty[i + 1, 1])), i))
            else:
                out.append((int(n), dl, dr, i))
        return out

    def speeds(self) -> np.ndarray:
        """(n-1) x 2: each wheel's mean speed over each interval between ticks (rad/s)."""
        return np.diff(self.angle, axis=0) / (np.diff(self.millis)[:, None] / 1000.0)


def degraded(run: Run, rng: np.random.Generator, *, quantum: int = 1, counts_per_rev: int | None = None,
             late: float = 0.0, late_ms: int = 2, drop: float = 0.0) -> Run:
    """``run`` as a poorer recording would give it: the counts floored to multiples of
    ``quantum`` (a coarser encoder); a share ``late`` of the ticks stamped up to
    ``late_ms`` ms after their counts were latched (a stamp that disagrees with its
    counts: the board's own lines cannot, as ``millis`` and the counts are taken in
    the same tick, but a logger that stamps lines as they arrive would); a share
    ``drop`` of the ticks lost (not the first)."""
    cpr = counts_per_rev or ChairParams().counts_per_rev
    step = 2.0 * math.pi * quantum / cpr
    angle = np.floor(np.round(run.angle / (2.0 * math.pi / cpr)) / quantum) * step
    millis = run.millis.copy()
    shifted = rng.random(len(millis)) < late
    shifted[0] = False
    millis[shifted] += rng.integers(1, late_ms + 1, size=int(shifted.sum()))
    keep = rng.random(len(millis)) >= drop
    keep[0] = True
    keep &= np.concatenate([[True], np.diff(millis) > 0])     # a late stamp may pass the next
    millis, duty, angle = millis[keep], run.duty[keep], angle[keep]
    return Run(millis=millis, duty=duty, angle=angle, blocks=run.blocks, name=run.name)
