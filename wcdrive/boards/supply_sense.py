"""The supply sense as the simulated boards wire it: the battery through the divider to
analog input A0 (``SUPPLY_CHANNEL``, ADC channel 0), AVcc (``AVCC_MV``) the reference.

``pin_millivolts(volts)`` is what a battery of ``volts`` puts on A0 (``plant_millivolts``:
the plant's battery as it last computed it, ``Plant.battery``), and
``adc_counts(millivolts)`` what the ADC makes of it in simavr 1.6, the compiled
firmware's chip; the port's tick takes the same count (``PortLoop``), so both read one
count for one battery. ``NOMINAL_MV`` is a 24 V battery at A0: where a board starts.
``SupplyOverrides`` is a caller's timeline of supply voltages that replace the plant's
(``PortLoop.set_supply``).

simavr samples lazily: it converts a channel's millivolts when the firmware reads ADCL
(``avr_adc_read_l``), not when the conversion starts, so a board reads the voltage on
the pin at the moment its tick reads the result.
"""

from __future__ import annotations

import bisect
from typing import TYPE_CHECKING

from wcdrive.firmware import constants as C

if TYPE_CHECKING:
    from wcdrive.plant import Plant

__all__ = ["AVCC_MV", "NOMINAL_MV", "SUPPLY_CHANNEL", "SupplyOverrides", "adc_counts", "pin_millivolts",
           "plant_millivolts"]

#: The ADC channel of the supply sense (A0).
SUPPLY_CHANNEL = C.PIN_SUPPLY
#: AVcc, the ADC's reference, in mV: the Mega's 5 V (the harness sets simavr's ``avcc``).
AVCC_MV = 5000
#: The ADC's full scale: simavr 1.6 scales by it, where the datasheet has 1024.
_FULL_SCALE = 0x3FF


def pin_millivolts(volts: float) -> int:
    """The millivolts a battery of ``volts`` puts on A0: ``volts / SUPPLY_DIVIDER``
    (100 kohm over 20 kohm), rounded to the mV, never below 0.

    simavr's analog inputs take whole millivolts; a mV at A0 is 6 mV of battery, a
    fifth of an ADC count."""
    return max(0, round(volts * 1000.0 / float(C.SUPPLY_DIVIDER)))


def plant_millivolts(plant: Plant) -> int:
    """The millivolts the plant's battery puts on A0 now: ``pin_millivolts`` of its
    terminal voltage over the plant's last step (``Plant.battery``; without a battery
    model, the ideal supply's). Both backends take the plant's battery from here."""
    return pin_millivolts(plant.battery[0])


def adc_counts(millivolts: int) -> int:
    """The count simavr 1.6's ADC reads for ``millivolts`` on a channel, AVcc the
    reference: ``millivolts * 1023 // AVCC_MV``, clipped to 1023.

    That is ``avr_adc_read_l``'s ``(mV * 0x3ff) / vref`` in 32-bit unsigned arithmetic.
    The chip itself (the datasheet's ``ADC = Vin * 1024 / Vref``) and the firmware's
    ``SUPPLY_VOLTS_PER_COUNT`` (5 V x 6 / 1024) scale by 1024: simavr reads about 0.1 %
    low (818 for 24 V where the datasheet gives 819, ``SUPPLY_NOMINAL_COUNTS``). Both
    backends read simavr's count, so they agree with each other, not with the chip's
    last count."""
    return min(_FULL_SCALE, max(0, int(millivolts)) * _FULL_SCALE // AVCC_MV)


#: A 24 V battery at A0 (4000 mV): every board starts there, so that a run without a
#: battery model or a supply of its own reads a healthy battery.
NOMINAL_MV = pin_millivolts(24.0)


class SupplyOverrides:
    """Battery voltages a caller sets from a cycle on, in place of the plant's: each
    change is (cycle, volts), or (cycle, None) to give the supply back to the plant.
    ``at(cycle)`` is what is in force at ``cycle``, asked in non-decreasing cycles."""

    def __init__(self) -> None:
        self._due: list[tuple[int, float | None]] = []
        self._now: float | None = None

    def set(self, cycle: int, volts: float | None) -> None:
        """From ``cycle`` on the supply is ``volts`` (None: the plant's); after the
        changes already set for the same cycle."""
        bisect.insort(self._due, (int(cycle), volts), key=lambda c: c[0])

    def at(self, cycle: int) -> float | None:
        """The volts set for ``cycle`` (None: none, the plant's); the changes due by then
        are made."""
        due = self._due
        while due and due[0][0] <= cycle:
            self._now = due.pop(0)[1]
        return self._now
