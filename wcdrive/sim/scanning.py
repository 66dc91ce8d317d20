"""The lidar in a simulated run: a ``ScanRecorder`` takes a scan every turn of the
lidar's head while the backend steps the plant, each beam cast at its own time from
where the chair then was.

The backend calls ``poll`` after every control tick (or physics step). Turns start at 0
and follow each other at the model's ``scan_hz``; once the plant has stepped past a
turn's end, the recorder takes the plant's motion log and makes the turn from it
(``wcdrive.plant.lidar.MotionTrack``): the poses integrated from the pose the plant
had at the last poll before the turn began (its ground truth, so no drift builds up
over a run), and the beams cast from them in C (``Lidar.scan``). Given a ``ScanPipe``,
each turn is made on its C thread while the run goes on, and collected when the next
turn is due (``Lidar.start_scan``: its noise drawn at once, so the scans are the same
with a pipe or without). A turn still under way when the run ends is not published, as
the driver publishes none; ``finish`` collects the last. The motion log
it took goes back to the runner (``motion``), which joins it to what is left at the
end: the run's ground truth is the same with the lidar on or off.
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


class ScanRecorder:
    """Takes ``lidar``'s scans of ``world`` as ``plant`` moves (module docstring);
    ``rng`` draws the range noise (None: none)."""

    def __init__(self, lidar: Lidar, world: World, plant: Plant, rng: np.random.Generator | None,
                 pipe: ScanPipe | None = None) -> None:
        self.lidar, self.world, self.plant, self.rng, self.pipe = lidar, world, plant, rng, pipe
        self.period = 1.0 / lidar.model.scan_hz
        self.scans: list[LaserScan] = []
        self._pending: list[PendingScan] = []
        self._taken: list[np.ndarray] = []         # every motion log row taken, in order
        self._rows: list[np.ndarray] = []          # those after the anchor
        self._anchor = (plant.pose, plant.time)    # a true pose at or before the next turn's start
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
        self._taken.append(rows)
        self._rows.append(rows)
        log = np.concatenate(self._rows) if len(self._rows) > 1 else rows
        pose, t_anchor = self._anchor
        track = MotionTrack(pose, t_anchor, log)
        self.finish()
        while now >= self._next_end - _EPS:
            t0 = self._turn * self.period
            self._pending.append(self.lidar.start_scan(self.world, track, t0, self.rng, self.pipe))
            self._turn += 1
            self._next_end = (self._turn + 1) * self.period
        # The next turn started before now: the anchor is the last knot at or before its
        # start, placed by the plant's true pose now and the motion integrated between the
        # two (so the integration's error never builds up from one turn to the next).
        t, x, y, heading = track.knots
        k = max(0, int(np.searchsorted(t, self._turn * self.period + _EPS, side="right")) - 1)
        back = _relative((float(x[-1]), float(y[-1]), float(heading[-1])),
                         (float(x[k]), float(y[k]), float(heading[k])))
        self._anchor = (_compose(plant.pose, back), float(t[k]))
        self._rows = [log[k:]] if k < len(log) else []

    def finish(self) -> None:
        """Collects the turns still being made (``scans`` has them all after)."""
        self.scans += [p.result() for p in self._pending]
        self._pending = []

    def motion(self) -> list[np.ndarray]:
        """The motion log rows taken so far (the runner joins them to the rest)."""
        return list(self._taken)


def scan_summary(scans: list[LaserScan]) -> dict[str, object]:
    """A run's scans in a few figures (``--json``): how many, the beams each (constant:
    a single figure, else the list of counts seen), the first and last stamps, the
    scan period, and the share of beams with a return."""
    if not scans:
        return {"lidar_scans": 0}
    beams = sorted({len(s.ranges) for s in scans})
    stamps = np.array([s.stamp for s in scans])
    returns = sum(int(np.isfinite(s.ranges).sum()) for s in scans)
    first = scans[0]
    return {
        "lidar_scans": len(scans),
        "lidar_beams": beams[0] if len(beams) == 1 else beams,
        "lidar_first_stamp_s": float(stamps[0]), "lidar_last_stamp_s": float(stamps[-1]),
        "lidar_scan_time_s": first.scan_time, "lidar_time_increment_s": first.time_increment,
        "lidar_range_min_m": first.range_min, "lidar_range_max_m": first.range_max,
        "lidar_return_fraction": returns / sum(len(s.ranges) for s in scans),
        "lidar_nearest_m": float(min((float(np.min(s.ranges)) for s in scans), default=math.inf)),
    }
