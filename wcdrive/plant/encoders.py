"""The signals an ideal quadrature encoder makes as its wheel turns: edge trains.

States are 2-bit numbers ``A << 1 | B``. Counting up (forward, as the seed's table
defines it) walks 11 -> 01 -> 00 -> 10 -> 11. The firmware's decoder for these
signals is ``wcdrive.firmware.quadrature``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: AB state for ``count % 4``: count 0 is 11, then 01, 00, 10.
STATE_OF_PHASE = (0b11, 0b01, 0b00, 0b10)
_STATE_OF_PHASE = np.array(STATE_OF_PHASE, dtype=np.int8)


def state_for_count(count: int | np.ndarray) -> int | np.ndarray:
    """The AB state an ideal encoder shows at a position (counts)."""
    phases = np.asarray(count) % 4
    result = _STATE_OF_PHASE[phases]
    return int(result) if np.ndim(result) == 0 else result


@dataclass(frozen=True)
class EdgeTrain:
    """Pin changes of one encoder: times in seconds and the AB state after each."""

    times: np.ndarray
    states: np.ndarray
    start_count: int
    end_count: int


def edges_from_trajectory(times: np.ndarray, counts: np.ndarray) -> EdgeTrain:
    """Edge times of an ideal encoder whose position (in counts, real-valued) moves
    linearly between the samples ``(times[i], counts[i])``.

    The integer position is ``floor(position)``; each crossing of an integer is one
    edge, in either direction, at the interpolated time.
    """
    times = np.asarray(times, dtype=np.float64)
    counts = np.asarray(counts, dtype=np.float64)
    if times.shape != counts.shape or times.ndim != 1 or times.size < 1:
        raise ValueError("times and counts must be 1-D arrays of the same length")
    if np.any(np.diff(times) < 0):
        raise ValueError("times must not decrease")
    position = np.floor(counts).astype(np.int64)
    edge_times: list[np.ndarray] = []
    edge_counts: list[np.ndarray] = []
    for i in range(times.size - 1):
        p0, p1 = position[i], position[i + 1]
        if p0 == p1:
            continue
        c0, c1 = counts[i], counts[i + 1]
        if p1 > p0:
            levels = np.arange(p0 + 1, p1 + 1)          # crossing level k going up: count becomes k
            after = levels
        else:
            levels = np.arange(p0, p1, -1)               # crossing level k going down: count becomes k-1
            after = levels - 1
        fraction = (levels - c0) / (c1 - c0)
        edge_times.append(times[i] + fraction * (times[i + 1] - times[i]))
        edge_counts.append(after)
    if edge_times:
        all_times = np.concatenate(edge_times)
        all_counts = np.concatenate(edge_counts)
    else:
        all_times = np.zeros(0)
        all_counts = np.zeros(0, dtype=np.int64)
    return EdgeTrain(
        times=all_times,
        states=np.asarray(state_for_count(all_counts), dtype=np.int64).reshape(-1),
        start_count=int(position[0]),
        end_count=int(position[-1]),
    )
