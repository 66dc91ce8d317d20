"""The firmware's quadrature decoder (the encoder ISRs of final_control.ino).

States are 2-bit numbers ``A << 1 | B``. Counting up (forward, as the seed's table
defines it) walks 11 -> 01 -> 00 -> 10 -> 11; a transition in which both channels
change is illegal: it is counted and leaves the position alone. The signals an encoder
makes are the plant's: ``wcdrive.plant.encoders``.
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

@dataclass
class QuadratureDecoder:
    """One wheel's interrupt routine: ``edge(state)`` per pin change."""

    last: int = 0b11
    count: int = 0
    illegal: int = 0

    def edge(self, state: int) -> None:
        """The ISR for one pin change; ``state`` is the AB state the pins now show."""
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
