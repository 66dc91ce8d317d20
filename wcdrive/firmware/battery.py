"""The supply as final_control.ino measures it, and what a low battery does: the sketch's
``updateSupply``, ``batteryShare``, ``batteryFault`` and the low-battery events
(docs/safety.md, "The battery").

Each tick reads the ADC count at PIN_SUPPLY (``supplyTick``: the conversion the last
tick started; the battery through a SUPPLY_DIVIDER divider, SUPPLY_VOLTS_PER_COUNT volts
a count) and low-passes it (``supplyVolts``, SUPPLY_FILTER a tick: a time constant of
1 s; the first reading stands as it is). The filter lets the sag of a start or a kerb
pass and keeps a climb's: what a battery gives under a sustained load.

Below BATTERY_LOW_V the low-battery rollback lowers the top speed, linearly to
BATTERY_SHARE_MIN of ``max_wheel`` at BATTERY_CUTOFF_V, the curvature kept
(``batteryShare``, one of the caps of ``capped_goals``); ``EVT:BATTERY,1`` when the
filtered supply falls below BATTERY_LOW_V, ``EVT:BATTERY,0`` when it is back
BATTERY_HYSTERESIS above it (a battery at rest recovers some of its sag): one a tick, in
the slot the wait for neutral uses. Below BATTERY_CUTOFF_V the ``UNDERVOLT`` fault
latches: the chair stops along the fault ramp and parks, held or braked. A supply sense
that reads nothing (a cut wire) reads 0 V: the fault.
"""

from __future__ import annotations

from wcdrive.avr.f32 import add, div, from_int, mul, sub
from wcdrive.firmware import constants as C
from wcdrive.firmware.output import send, send_event
from wcdrive.firmware.state import FirmwareState

__all__ = ["FAULT_UNDERVOLT", "battery_fault", "battery_share", "send_battery_event",
           "update_supply"]

FAULT_UNDERVOLT = 0x2000


def update_supply(s: FirmwareState) -> None:
    """``updateSupply``: the filtered supply a tick on, from ``supplyTick``; the
    rollback's start and end, their events pending."""
    volts = mul(from_int(s.supplyTick), C.SUPPLY_VOLTS_PER_COUNT)
    if s.supplyVolts == 0.0:
        s.supplyVolts = volts
    else:
        s.supplyVolts = add(s.supplyVolts, mul(C.SUPPLY_FILTER, sub(volts, s.supplyVolts)))
    if not s.batteryLow and s.supplyVolts < C.BATTERY_LOW_V:
        s.batteryLow = 1
        s.batteryPending |= 1
    elif s.batteryLow and s.supplyVolts > C.BATTERY_LOW_END:
        s.batteryLow = 0
        s.batteryPending |= 2


def battery_share(s: FirmwareState) -> float:
    """``batteryShare``: the top wheel speed the filtered supply allows, of
    ``max_wheel``: 1 from BATTERY_LOW_V up, BATTERY_SHARE_MIN at BATTERY_CUTOFF_V and
    below, linear between."""
    if s.supplyVolts >= C.BATTERY_LOW_V:
        return 1.0
    k = div(sub(C.BATTERY_LOW_V, s.supplyVolts), C.BATTERY_SPAN)
    if k > 1.0:
        k = 1.0
    return sub(1.0, mul(k, C.BATTERY_SHARE_SPAN))


def battery_fault(s: FirmwareState) -> int:
    """``batteryFault``: FAULT_UNDERVOLT with the filtered supply below
    BATTERY_CUTOFF_V."""
    return FAULT_UNDERVOLT if s.supplyVolts < C.BATTERY_CUTOFF_V else 0


def send_battery_event(s: FirmwareState, out: bytearray) -> None:
    """The lowest pending rollback event: ``EVT:BATTERY,1`` (on), ``EVT:BATTERY,0``."""
    if s.batteryPending & 1:
        s.batteryPending &= 2
        send(s, send_event("BATTERY,1"), out)
    else:
        s.batteryPending = 0
        send(s, send_event("BATTERY,0"), out)
