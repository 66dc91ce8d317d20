"""The lidar in a simulated run: the ``ScanRecorder`` (``wcdrive.plant.scan_recorder``)
the backends poll, and a run's scans in a few figures (``scan_summary``)."""

from __future__ import annotations

import math

import numpy as np

from wcdrive.plant.lidar import LaserScan
from wcdrive.plant.scan_recorder import ScanRecorder

__all__ = ["ScanRecorder", "scan_summary"]


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
