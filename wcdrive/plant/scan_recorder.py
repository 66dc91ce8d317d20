"""Scans as the chair moves: a ``ScanRecorder`` takes a lidar's scan every turn of its
head while something steps the plant (a scenario's backend, a live simulated board),
each beam cast at its own time from where the chair then was.

    recorder = ScanRecorder(lidar, world, plant, rng)     # plant.start_motion_log() first
    ...                                                   # the plant steps
    recorder.poll()                                       # after each step, or slice of steps
    new = recorder.take()                                 # the turns made since the last take

The caller calls ``poll`` after every control tick (or physics step). Turns start at 0
and follow each other at the model's ``scan_hz``; once the plant has stepped past a
turn's end, the recorder takes the plant's motion log and makes the turn from it
(``wcdrive.plant.lidar.MotionTrack``): the poses integrated from the pose the plant
had at the last poll before the turn began (its ground truth, so no drift builds up
over a run), and the beams cast from them in C (``Lidar.scan``). Given a ``ScanPipe``,
each turn is made on its C thread while the run goes on, and collected when the next
turn is due (``Lidar.start_scan``: its noise drawn at once, so the scans are the same
with a pipe or without). A turn still under way when the run ends is not published, as
the driver publishes none; ``finish`` collects the last. With ``keep_motion`` the
motion log it took is kept for the caller (``motion``: a scenario's runner joins it to
what is left at the end, so the run's ground truth is the same with the lidar on or
off); a live board, which runs for hours, keeps none, and ``take`` hands its scans on.
"""

from __future__ import annotations

import math

import numpy as np

from wcdrive.plant.chair import Plant
from wcdrive.plant.lidar import LaserScan, Lidar, MotionTrack, PendingScan
from wcdrive.plant.raycast import ScanPipe
from wcdrive.plant.world import World

#: s: a poll this close after a turn's end counts as at it (the plant's clock is a sum of steps).
_EPS = 1e-9


def _compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


def _relative(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, b[2] - a[2])


class _Anchor:
    """The anchor at knot ``k`` of ``track``, whose last knot is where the plant was
    (``pose``)."""

    def __init__(self, track: MotionTrack, k: int, pose: tuple[float, float, float]) -> None:
        self.track, self.k, self.at_end = track, k, pose

    def pose(self) -> tuple[tuple[float, float, float], float]:
        t, x, y, heading = self.track.knots
        k = self.k
        back = _relative((float(x[-1]), float(y[-1]), float(heading[-1])),
                         (float(x[k]), float(y[k]), float(heading[k])))
        return _compose(self.at_end, back), float(t[k])


class ScanRecorder:
    """Takes ``lidar``'s scans of ``world`` as ``plant`` moves (module docstring);
    ``rng`` draws the range noise (None: none)."""

    def __init__(self, lidar: Lidar, world: World, plant: Plant, rng: np.random.Generator | None,
                 pipe: ScanPipe | None = None, keep_motion: bool = True) -> None:
        self.lidar, self.world, self.plant, self.rng, self.pipe = lidar, world, plant, rng, pipe
        self.keep_motion = keep_motion
        self.period = 1.0 / lidar.model.scan_hz
        self.scans: list[LaserScan] = []
        self._pending: list[PendingScan] = []
        self._taken: list[np.ndarray] = []         # every motion log row taken, in order
        self._rows: list[np.ndarray] = []          # those after the anchor
        # a true pose at or before the next turn's start, or what it is worked out from
        # once the turns that integrate its track are made
        self._anchor: tuple[tuple[float, float, float], float] | _Anchor = (plant.pose, plant.time)
        self._turn = 0
        self._next_end = self.period

    def poll(self) -> None:
        """Called after the plant stepped: makes every turn that has ended."""
        plant = self.plant
        now = plant.time
        start = self._turn * self.period
        if now <= start + _EPS:
            self._anchor = (plant.pose, now)
            return
        if now < self._next_end - _EPS:
            return
        rows = plant.take_motion_log()
        if self.keep_motion:
            self._taken.append(rows)
        self._rows.append(rows)
        log = np.concatenate(self._rows) if len(self._rows) > 1 else rows
        self.finish()
        anchor = self._anchor
        pose, t_anchor = anchor.pose() if isinstance(anchor, _Anchor) else anchor
        track = MotionTrack(pose, t_anchor, log)
        while now >= self._next_end - _EPS:
            t0 = self._turn * self.period
            self._pending.append(self.lidar.start_scan(self.world, track, t0, self.rng, self.pipe))
            self._turn += 1
            self._next_end = (self._turn + 1) * self.period
        # The next turn started before now: the anchor is the last knot at or before its
        # start, placed by the plant's true pose now and the motion integrated between the
        # two (so the integration's error never builds up from one turn to the next); the
        # knots are those the turns just started integrate, read once they are made.
        start = self._turn * self.period + _EPS
        k = int(t_anchor <= start) + int(np.searchsorted(log[:, 0], start, side="right")) - 1
        k = max(0, k)
        self._anchor = _Anchor(track, k, plant.pose)
        self._rows = [log[k:]] if k < len(log) else []

    def finish(self) -> None:
        """Collects the turns still being made (``scans`` has them all after)."""
        self.scans += [p.result() for p in self._pending]
        self._pending = []

    def take(self) -> list[LaserScan]:
        """The scans made since the last ``take`` (the turns that have ended), oldest first."""
        self.finish()
        out, self.scans = self.scans, []
        return out

    def motion(self) -> list[np.ndarray]:
        """The motion log rows taken so far (the runner joins them to the rest; none
        without ``keep_motion``)."""
        return list(self._taken)
