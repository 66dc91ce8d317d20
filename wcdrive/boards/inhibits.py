"""The inhibit inputs on a simulated board's pins: which input is which (``INPUTS``:
1 the charger, 2 the seat raised; protocol/spec.toml, ``PIN_INHIBIT_1``/``_2``), a
change of one (``InhibitChange``: from ``at`` s the input is active, its pin pulled
LOW, or released), and what a timeline of changes holds at a moment
(``active_bits``: bit 0 input 1, bit 1 input 2, as the firmware's tick reads them).

The port takes the bits as its tick's input (``PortLoop``); the compiled firmware in
simavr reads the pins themselves (``VirtualMega.set_pin``), so a scenario's
``[[input]]`` timeline drives both alike.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["INPUTS", "LEVER_INPUT", "InhibitChange", "active_bits", "input_number"]

#: The inhibit inputs by name; "push" is the parking brake's manual-release lever, which
#: the board reads as a third inhibit input (push mode) and which releases the brake.
INPUTS = {"charger": 1, "seat": 2, "push": 4}
#: The lever's number: a change of it moves the plant's lever (``Plant.set_brake_lever``),
#: whose switch the board reads.
LEVER_INPUT = 4


def input_number(name: str | int) -> int:
    """1, 2 or 4, from an input's name (``INPUTS``) or number; ``ValueError`` otherwise."""
    if isinstance(name, int) and not isinstance(name, bool) and name in INPUTS.values():
        return name
    if isinstance(name, str) and name in INPUTS:
        return INPUTS[name]
    raise ValueError(f"no inhibit input {name!r}: {', '.join(INPUTS)} (or 1, 2, 4)")


@dataclass(frozen=True)
class InhibitChange:
    """From ``at`` s on, inhibit input ``number`` (1 or 2; 3, the brake driver's status, in the
    lock-step traces) is ``active`` (pulled LOW) or not."""

    at: float
    number: int
    active: bool

    def cycle(self, f_cpu: int) -> int:
        """The change's cycle at ``f_cpu``."""
        return round(self.at * f_cpu)

    def applied_to(self, bits: int) -> int:
        """``bits`` (bit 0 input 1, bit 1 input 2) with this change made."""
        mask = 1 << (self.number - 1)
        return bits | mask if self.active else bits & ~mask


def active_bits(changes: Iterable[InhibitChange], t: float) -> int:
    """The inputs active at ``t`` s by ``changes`` (in any order; each input starts
    released): bit 0 input 1, bit 1 input 2."""
    bits = 0
    for change in sorted(changes, key=lambda c: c.at):
        if change.at > t:
            break
        bits = change.applied_to(bits)
    return bits
