"""The firmware's quadrature decoder (the encoder ISRs of final_control.ino).

States are 2-bit numbers ``A << 1 | B``. Counting up (forward, as the seed's table
defines it) walks 11 -> 01 -> 00 -> 10 -> 11; a transition in which both channels
change is illegal: it is counted and leaves the position alone. The signals an encoder
makes are the plant's: ``wcdrive.plant.encoders``.

Storm guard: the ISRs count their edges per window of one Timer0 period (1.024 ms;
``TIMER0_COMPA`` clears the counts at Timer0 count ``STORM_COMPARE``, see
``wcdrive.avr.timer0.storm_window``). The ``STORM_EDGES``-th edge of one encoder in one
window (more than twice the wheel's top speed: a loose connector, EMI) masks that
encoder's two interrupts and sets ``storm``. From then on the encoder costs the CPU
nothing; the control tick latches the flag as an implausible-encoder fault, and
``reset`` (``unmask``) turns the interrupts back on. So no edge rate can hold ``loop()``
for longer than ``STORM_EDGES`` interrupts per encoder.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wcdrive.firmware.constants import STORM_EDGES

ILLEGAL = 2
#: ``QUAD_TABLE[(previous << 2) | current]``, as in final_control.ino.
QUAD_TABLE = (0, -1, +1, ILLEGAL, +1, 0, ILLEGAL, -1, -1, ILLEGAL, 0, +1, ILLEGAL, +1, -1, 0)
#: Transitions (indices into QUAD_TABLE) that step forward, backward, or are illegal.
_FORWARD = tuple(i for i, v in enumerate(QUAD_TABLE) if v == +1)
_BACKWARD = tuple(i for i, v in enumerate(QUAD_TABLE) if v == -1)
_ILLEGALS = tuple(i for i, v in enumerate(QUAD_TABLE) if v == ILLEGAL)

@dataclass
class QuadratureDecoder:
    """One wheel's interrupt routine: ``edge(state, window)`` per pin change, with the
    storm guard (module docstring): ``storm`` is set, and the routine no longer runs,
    at the ``STORM_EDGES``-th edge within one Timer0 window."""

    last: int = 0b11
    count: int = 0
    illegal: int = 0
    storm: bool = False
    window: int = -(2**62)
    window_edges: int = 0

    def edge(self, state: int, window: int | None = None) -> None:
        """The ISR for one pin change; ``state`` is the AB state the pins now show and
        ``window`` the Timer0 window it falls in (``storm_window(cycle)``; None: the
        storm guard is not modelled). A masked encoder (``storm``) runs no ISR."""
        if self.storm:
            return
        step = QUAD_TABLE[(self.last << 2) | state]
        if step == ILLEGAL:
            self.illegal += 1
        else:
            self.count = _wrap_i32(self.count + step)
        self.last = state
        if window is None:
            return
        if window != self.window:
            self.window, self.window_edges = window, 0
        self.window_edges += 1
        if self.window_edges >= STORM_EDGES:
            self.storm = True

    def edges_in_windows(self, states: np.ndarray, windows: np.ndarray) -> None:
        """``edge`` over arrays of states and their Timer0 windows (non-decreasing): fast
        (``bulk``) up to the edge at which the storm guard trips, if it does."""
        states = np.asarray(states, dtype=np.int64)
        windows = np.asarray(windows, dtype=np.int64)
        n = states.size
        if n == 0 or self.storm:
            return
        # Rank of each edge within its window, counting the edges already seen in the
        # current window.
        new = np.concatenate(([windows[0] != self.window], windows[1:] != windows[:-1]))
        starts = np.flatnonzero(new)
        index = np.arange(n)
        run_start = starts[np.searchsorted(starts, index, "right") - 1] if starts.size else np.zeros(n, int)
        rank = index - run_start + 1
        if not new[0]:
            first_run = index < (starts[0] if starts.size else n)
            rank = np.where(first_run, index + 1 + self.window_edges, rank)
        tripped = np.flatnonzero(rank >= STORM_EDGES)
        stop = int(tripped[0]) + 1 if tripped.size else n
        self.bulk(states[:stop])
        self.window = int(windows[stop - 1])
        self.window_edges = int(rank[stop - 1])
        if tripped.size:
            self.storm = True

    def bulk(self, states: np.ndarray) -> None:
        """Feeds a sequence of pin states at once, without the storm guard; identical to
        calling ``edge`` on each: a histogram of the 16 transitions gives the steps and
        the illegal ones."""
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

    def unmask(self, state: int) -> None:
        """``reset``: the interrupts on again, the pins read afresh."""
        self.storm = False
        self.last = state
        self.window_edges = 0


def _wrap_i32(value: int) -> int:
    return (value + 2**31) % 2**32 - 2**31
