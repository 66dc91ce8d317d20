"""A lidar on a live simulated board: its scans made as the board's thread steps the
plant, kept for the host to take.

    board = SimulatedBoard(world=World.from_file("room.toml"), start=(4.0, 1.2, 0.0),
                           lidar=Lidar(RPLIDAR_S3, SEED_MOUNT)).start()
    scans = board.lidar.take()        # the scans made since the last take, oldest first

The sensor lives in the plant, not in the firmware: a real chair's lidar has its own
USB link to the computer, not the Mega's serial line. The scans are made by a
``ScanRecorder`` (each beam cast at its own time from where the chair then was, as the
device's are), polled by the board's thread after each step under the board's lock;
their ``stamp`` is the plant's clock (the board's simulated seconds, which run on
across board resets). Up to ``keep`` scans wait for the host (the newest; a host that
does not take them loses the oldest, counted in ``dropped``), so a board that runs for
hours holds a bounded few.
"""

from __future__ import annotations

import threading
from collections import deque

import numpy as np

from wcdrive.plant import Plant
from wcdrive.plant.lidar import LaserScan, Lidar
from wcdrive.plant.scan_recorder import ScanRecorder
from wcdrive.plant.world import World

#: Scans a live board keeps for its host (5 s of the S3's 10 Hz).
KEEP_SCANS = 50


class BoardLidar:
    """``lidar`` on ``plant``, casting into ``world``; its range noise from ``seed``."""

    def __init__(self, lidar: Lidar, world: World, plant: Plant, seed: int = 0,
                 keep: int = KEEP_SCANS) -> None:
        self.lidar = lidar
        plant.start_motion_log()
        self._recorder = ScanRecorder(lidar, world, plant, np.random.default_rng(seed), keep_motion=False)
        self._ready: deque[LaserScan] = deque(maxlen=keep)
        self._lock = threading.Lock()
        #: scans made but never taken, the board's buffer being full
        self.dropped = 0

    def poll(self) -> None:
        """Makes the turns that ended (the board's thread, after a step)."""
        self._recorder.poll()
        new = self._recorder.take()
        if not new:
            return
        with self._lock:
            overflow = len(self._ready) + len(new) - (self._ready.maxlen or 0)
            self.dropped += max(0, overflow)
            self._ready.extend(new)

    def take(self) -> list[LaserScan]:
        """The scans made since the last ``take``, oldest first (any thread)."""
        with self._lock:
            out = list(self._ready)
            self._ready.clear()
        return out
