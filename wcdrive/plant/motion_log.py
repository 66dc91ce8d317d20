"""The plant's motion log (``Plant.start_motion_log``): a row a step, ``(time, forward,
lateral, yaw rate, volts left, volts right)``, the axle midpoint's motion after the
step and the motor voltages over it; the ground truth of the fault metrics and the
lidar's poses.

``MotionLog`` takes whole blocks of rows (``append``: ``Plant.advance``'s arrays) and
hands out room for rows the kernel writes in place (``reserve``:
``Plant.advance_batch``); ``take`` gives the rows so far in step order, as one array,
and empties the log.

Why the two: ``advance_batch`` runs every control tick, a few steps at a time, for
hours; an array a call would cost more than its steps. Its rows go into a chunk of
``CHUNK_ROWS`` rows the log keeps, by address, and the chunk joins the blocks when it is
full or a block or a ``take`` comes after it.
"""

from __future__ import annotations

import numpy as np

#: Values a row.
COLUMNS = 6
#: Rows of the chunk ``reserve`` writes into (more if one call asks for more).
CHUNK_ROWS = 1 << 14


class MotionLog:
    """The rows of the steps since it was made or last taken (module docstring)."""

    def __init__(self) -> None:
        self._blocks: list[np.ndarray] = []
        self._chunk = np.empty((0, COLUMNS))
        self._rows = 0                  # of the chunk written
        self._at = 0                    # the chunk's address

    def append(self, block: np.ndarray) -> None:
        """Rows (``n x 6``) after those logged so far; kept, not copied."""
        self.close_chunk()
        self._blocks.append(block)

    def reserve(self, n: int) -> int:
        """The address of room for ``n`` rows (``n x 6`` float64, row-major) after those
        logged so far, to be written before the next call on the log."""
        if self._rows + n > self._chunk.shape[0]:
            self.close_chunk()
            self._chunk = np.empty((max(n, CHUNK_ROWS), COLUMNS))
            self._at = int(self._chunk.__array_interface__["data"][0])
        at = self._at + 8 * COLUMNS * self._rows
        self._rows += n
        return at

    def close_chunk(self) -> None:
        """The rows written into the chunk join the blocks; later rows go to a new one."""
        if self._rows:
            self._blocks.append(self._chunk[:self._rows])
            self._chunk = np.empty((0, COLUMNS))
            self._rows = 0

    def take(self) -> np.ndarray:
        """The rows logged so far (an ``n x 6`` array, ``0 x 6`` for none); the log is
        then empty."""
        self.close_chunk()
        if not self._blocks:
            return np.zeros((0, COLUMNS))
        out = np.concatenate(self._blocks)
        self._blocks = []
        return out
