"""Quadrature encoders: the firmware's 4-bit decoder and the signals an encoder makes.

States are 2-bit numbers ``A << 1 | B``. Counting up (forward, as the seed's table
defines it) walks 11 -> 01 -> 00 -> 10 -> 11; a transition in which both channels
change is illegal: it is counted and leaves the position alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ILLEGAL = 2
#: ``QUAD_TABLE[(previous << 2) | current]``, as in final_control.ino.
QUAD_TABLE = (0, -1, +1, ILLEGAL, +1, 0, ILLEGAL, -1, -1, ILLEGAL, 0, +1, ILLEGAL, +1, -1, 0)
#: Transitions (indices into QUAD_TABLE) that step forward, backward, or are illegal.
_FORWARD = tuple(i for i, v in enumerate(QUAD_TABLE) if v == +1)
_BACKWARD = tuple(i for i, v in enumerate(QUAD_TABLE) if v == -1)
_ILLEGALS = tuple(i for i, v in enumerate(QUAD_TABLE) if v == ILLEGAL)

#: AB state for ``count % 4``: count 0 is 11, then 01, 00, 10.
STATE_OF_PHASE = (0b11, 0b01, 0b00, 0b10)
_STATE_OF_PHASE = np.array(STATE_OF_PHASE, dtype=np.int8)


@dataclass
class QuadratureDecoder:
    """One wheel's interrupt routine: ``edge(state)`` per pin change."""

    last: int = 0b11
    count: int = 0
    illegal: int = 0

    def edge(self, state: int) -> None:
        step = QUAD_TABLE[(self.last << 2) | state]
        if step == ILLEGAL:
            self.illegal += 1
        else:
            self.count = _wrap_i32(self.count + step)
        self.last = state

    def bulk(self, states: np.ndarray) -> None:
        """Feeds a sequence of pin states at once; identical to calling ``edge`` on each:
        a histogram of the 16 transitions gives the steps and the illegal ones."""
        states = np.asarray(states)
        if states.size == 0:
            return
        if states.dtype != np.int8:
            states = states.astype(np.int8)
        hist = np.bincount((states[:-1] << 2) | states[1:], minlength=16).tolist()
        hist[(self.last << 2) | int(states[0])] += 1
        steps = sum(hist[i] for i in _FORWARD) - sum(hist[i] for i in _BACKWARD)
        self.illegal += sum(hist[i] for i in _ILLEGALS)
        self.count = _wrap_i32(self.count + steps)
        self.last = int(states[-1])


def _wrap_i32(value: int) -> int:
    return (value + 2**31) % 2**32 - 2**31


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
