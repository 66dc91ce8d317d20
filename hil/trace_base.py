"""The two things every trace generator shares: a source of choices (``Draw``:
``RandomDraw`` seeded, ``HypothesisDraw`` for property tests, which then shrink) and
the trace itself (``Trace``: serial writes and encoder edges on a timeline, resets,
storms). ``wcdrive.hil.traces`` builds random traces from them, ``wcdrive.hil.profiles``
the motion profiles a trace may end in.
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from wcdrive.firmware.constants import SUPPLY_DIVIDER
from wcdrive.plant.encoders import EdgeTrain

T = TypeVar("T")

#: When the first byte may arrive: setup() is done after about 2 ms.
FIRST_COMMAND_S = 0.010
#: Edges/s per wheel in generated traces (the wheel's top speed is 28,000). The firmware
#: counts every edge up to 70,000 edges/s on both wheels at once on a quiet line
#: (tests/boards/test_harness.py), but only up to about 57,900 while the RX ring
#: overflows: an edge of the left encoder may wait for the receive interrupt's longest
#: path and the right encoder's interrupt before its own reads the pins, and the next
#: edge must come later than that (tests/firmware/test_firmware_timing.py works it out
#: from the ELF). 60,000 merged edges under a flood; 50,000 keeps 16 % in hand.
MAX_TRACE_EDGE_RATE = 50000.0


class Draw(Protocol):
    """A source of choices: ``RandomDraw`` or ``HypothesisDraw``."""

    def integer(self, lo: int, hi: int) -> int:
        """An integer in [lo, hi]."""

    def real(self, lo: float, hi: float) -> float:
        """A float in [lo, hi]."""

    def choice(self, options: Sequence[T]) -> T:
        """One of ``options``."""

    def boolean(self, p: float = 0.5) -> bool:
        """True with probability ``p``."""


class RandomDraw:
    """Choices from ``random.Random(seed)``: one seed, one trace."""

    def __init__(self, seed: int, *, eeprom_commands: bool = True, floods: bool = True,
                 profiles: bool = True) -> None:
        """``eeprom_commands=False``: the generator as it was before ``save`` and
        ``defaults``; ``floods=False``: as it was before ``flood``; ``profiles=False``:
        as it was before ``motion_profile``; so that a seed found then gives the same
        trace."""
        self.rng = random.Random(seed)
        self.eeprom_commands = eeprom_commands
        self.floods = floods
        self.profiles = profiles

    def integer(self, lo: int, hi: int) -> int:
        """An integer in [lo, hi]."""
        return self.rng.randint(lo, hi)

    def real(self, lo: float, hi: float) -> float:
        """A float in [lo, hi]."""
        return self.rng.uniform(lo, hi)

    def choice(self, options: Sequence[T]) -> T:
        """One of ``options``."""
        return options[self.rng.randrange(len(options))]

    def boolean(self, p: float = 0.5) -> bool:
        """True with probability ``p``."""
        return self.rng.random() < p


class HypothesisDraw:
    """Choices drawn from ``st.data()``, so hypothesis can shrink a failing trace."""

    def __init__(self, data: Any) -> None:
        from hypothesis import strategies as st

        self._st = st
        self._data = data

    def integer(self, lo: int, hi: int) -> int:
        """An integer in [lo, hi]."""
        return self._data.draw(self._st.integers(lo, hi))

    def real(self, lo: float, hi: float) -> float:
        """A float in [lo, hi] (never NaN)."""
        return self._data.draw(self._st.floats(lo, hi, allow_nan=False))

    def choice(self, options: Sequence[T]) -> T:
        """One of ``options``."""
        return options[self._data.draw(self._st.integers(0, len(options) - 1))]

    def boolean(self, p: float = 0.5) -> bool:
        """True with probability ``p`` (in steps of 0.001)."""
        return self._data.draw(self._st.integers(0, 999)) < int(p * 1000)


@dataclass
class Trace:
    """The firmware's inputs: serial writes as (s, bytes), an encoder edge train per
    side, and ``millis_start``, the ``millis()`` set at ``main()`` (None: boot at 0)."""

    duration: float
    serial: list[tuple[float, bytes]] = field(default_factory=list)
    encoders: dict[str, EdgeTrain] = field(default_factory=dict)
    millis_start: int | None = None
    #: Encoder storms in the trains (``storm``): (side, start s, end s).
    storms: list[tuple[str, float, float]] = field(default_factory=list)
    #: The EEPROM's contents at power-on (``EEPROM_SIZE`` bytes; None: erased).
    eeprom: bytes | None = None
    #: Resets of the board during the trace (``VirtualMega.reset``): (s, cause).
    resets: list[tuple[float, str]] = field(default_factory=list)
    #: The motion profile the trace ends in (one of ``PROFILES``; None: none), and from when.
    profile: str | None = None
    profile_start: float = 0.0
    #: The inhibit inputs' changes: (s, input 1 or 2, active); each starts released.
    inhibits: list[tuple[float, int, bool]] = field(default_factory=list)
    #: Globals set at the entry of the first control tick from t s on, alike on the board
    #: and the port: (s, {name: value}). States a trace of a few seconds cannot reach
    #: otherwise (a motor hot from a long climb).
    pokes: list[tuple[float, dict[str, float | int]]] = field(default_factory=list)
    #: The supply sense's changes: (s, mV at A0, ``wcdrive.boards.supply_sense``); the
    #: board starts at a 24 V battery's ``NOMINAL_MV``.
    supply: list[tuple[float, int]] = field(default_factory=list)
    #: The motors' current senses' changes: (s, side, mV at A1 left or A2 right,
    #: ``wcdrive.boards.current_sense``); the board starts at 0 A (``ZERO_MV``).
    currents: list[tuple[float, str, int]] = field(default_factory=list)

    def describe(self) -> str:
        """The trace as text for a failure report, one serial write a line."""
        lines = [f"duration={self.duration}s millis_start={self.millis_start}"]
        if self.profile is not None:
            lines.append(f"  ends in the motion profile {self.profile!r} from t={self.profile_start:.4f}s")
        if self.eeprom is not None:
            lines.append(f"  EEPROM at power-on: {self.eeprom[:48].hex()}...")
        lines += [f"  t={t:.4f}s {data!r}" for t, data in self.serial]
        for side, train in self.encoders.items():
            lines.append(f"  {side}: {train.times.size} edges, count {train.start_count}"
                         f" -> {train.end_count}")
        lines += [f"  reset ({cause}) at t={t:.4f}s" for t, cause in self.resets]
        lines += [f"  storm on {side} from {a:.4f}s to {b:.4f}s" for side, a, b in self.storms]
        lines += [f"  inhibit {n} {'active' if on else 'released'} at t={t:.4f}s"
                  for t, n, on in self.inhibits]
        lines += [f"  set {values} at the first tick from t={t:.4f}s" for t, values in self.pokes]
        lines += [f"  supply {mv} mV at A0 ({mv * float(SUPPLY_DIVIDER) / 1000:.2f} V) from t={t:.4f}s"
                  for t, mv in self.supply]
        lines += [f"  {side} current sense {mv} mV from t={t:.4f}s" for t, side, mv in self.currents]
        return "\n".join(lines)


def spaced(changes: list[tuple[float, int]], least: float) -> list[tuple[float, int]]:
    """Changes of a pin's level, (s, mV), in time order, each kept only when it comes at
    least ``least`` s after the last kept: so that a tick reads the level before a change
    or after it."""
    kept: list[tuple[float, int]] = []
    for at, mv in sorted(changes):
        if not kept or at - kept[-1][0] >= least:
            kept.append((at, mv))
    return kept
