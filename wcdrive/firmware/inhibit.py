"""The inhibit inputs, as the sketch's ``updateInhibits``, ``inhibitShare`` and the
tick's inhibit event (docs/safety.md, "Inhibit inputs").

Two pins, read by each control tick (bit 0 input 1, bit 1 input 2; 1: active, the pin
pulled LOW), count once they have read their new level for INHIBIT_DEBOUNCE_TICKS
ticks in a row. Engaged, an input of speed 0 (INHIBIT_n_SPEED) stops the chair along
the normal ramp and the motion gate refuses anything but a stop (``ERR:inhibit``);
any other caps the faster wheel at its share of ``max_wheel``, the curvature kept. A
latching input (INHIBIT_n_LATCH) stays engaged until it is released and a ``reset``
comes. Released, the chair stops (the normal ramp) and motion needs a neutral command
first. Each change is an
``EVT:INHIBIT,<n>,<1 on|0 off>``, one a tick in the slot the wait for neutral uses.
"""

from __future__ import annotations

from wcdrive.avr.f32 import div, mul
from wcdrive.firmware import constants as C
from wcdrive.firmware.battery import battery_share
from wcdrive.firmware.drive import damped_targets, drive_caps
from wcdrive.firmware.motion import PIVOT_NONE, require_neutral
from wcdrive.firmware.output import send, send_event
from wcdrive.firmware.state import FirmwareState
from wcdrive.firmware.thermal import thermal_share

__all__ = ["capped_goals", "drive_inhibited", "inhibit_engaged", "send_inhibit_event", "update_inhibits"]

#: The events by their pending bit.
_EVENTS = {1: "INHIBIT,1,1", 2: "INHIBIT,1,0", 4: "INHIBIT,2,1", 8: "INHIBIT,2,0", 16: "PUSH,1", 32: "PUSH,0"}


def inhibit_engaged(s: FirmwareState) -> int:
    """``inhibitEngaged``: the inputs engaged (debounced, or latched)."""
    return s.inhibitStable | s.inhibitLatched


def drive_inhibited(s: FirmwareState) -> bool:
    """An engaged input of speed 0: the motion gate refuses anything but a stop."""
    return bool(inhibit_engaged(s) & C.INHIBIT_STOP_MASK)


def debounce_inhibit(s: FirmwareState, bit: int, count: int) -> int:
    """``debounceInhibit``: the input's new count (``inhibitStable`` flipped once the
    read level has differed for INHIBIT_DEBOUNCE_TICKS ticks)."""
    if (s.inhibitTick & bit) == (s.inhibitStable & bit):
        return 0
    count = (count + 1) & 0xFF
    if count >= C.INHIBIT_DEBOUNCE_TICKS:
        s.inhibitStable ^= bit
        return 0
    return count


def update_inhibits(s: FirmwareState) -> None:
    """``updateInhibits``: debounce and latch. An input of speed 0 that engages stops
    the chair as a stop command would (the normal ramp); so does one released (the
    command from before it no longer drives), which asks for neutral too; the change's
    events pend."""
    before = s.inhibitOn                # a reset may have ended a latch since
    s.inhibitCountL = debounce_inhibit(s, 1, s.inhibitCountL)
    s.inhibitCountR = debounce_inhibit(s, 2, s.inhibitCountR)
    s.inhibitCountP = debounce_inhibit(s, C.INHIBIT_PUSH, s.inhibitCountP)
    s.inhibitLatched |= s.inhibitStable & C.INHIBIT_LATCH_MASK
    after = inhibit_engaged(s)
    s.inhibitOn = after
    on, off = after & ~before & 7, before & ~after & 7
    if on & C.INHIBIT_STOP_MASK or off:
        s.targetL = s.targetR = 0.0
        s.pivotPhase = PIVOT_NONE
        s.pivotTicksLeft = 0
        s.lastTravel = 0.0
    if off:
        require_neutral(s)
    s.inhibitPending |= ((on & 1) | (off & 1) << 1 | (on & 2) << 1 | (off & 2) << 2
                         | (on & C.INHIBIT_PUSH) << 2 | (off & C.INHIBIT_PUSH) << 3)


def send_inhibit_event(s: FirmwareState, out: bytearray) -> None:
    """The lowest pending inhibit event."""
    bit = s.inhibitPending & -s.inhibitPending
    s.inhibitPending &= ~bit & 0xFF
    send(s, send_event(_EVENTS[bit]), out)


def inhibit_share(s: FirmwareState) -> float:
    """``inhibitShare``: the top wheel speed the engaged inputs allow, of ``max_wheel``."""
    engaged = inhibit_engaged(s)
    share = 1.0
    if engaged & 1 and C.INHIBIT_1_SPEED < share:
        share = C.INHIBIT_1_SPEED
    if engaged & 2 and C.INHIBIT_2_SPEED < share:
        share = C.INHIBIT_2_SPEED
    return share


def capped_goals(s: FirmwareState) -> tuple[float, float]:
    """What the setpoints ramp toward: the targets, through the tremor damping
    (``damped_targets``), within the drive limits (``drive_caps``), the faster wheel
    capped at the engaged inputs' share of ``max_wheel``, or the thermal or the
    low-battery rollback's if lower, with the curvature kept."""
    goal_l, goal_r = drive_caps(s, *damped_targets(s))
    share = inhibit_share(s)
    hot = thermal_share(s)
    if hot < share:
        share = hot
    low = battery_share(s)
    if low < share:
        share = low
    if share < 1.0:
        cap = mul(s.maxWheel, share)
        peak = abs(goal_l) if abs(goal_l) > abs(goal_r) else abs(goal_r)
        if peak > cap:
            k = div(cap, peak)
            goal_l, goal_r = mul(goal_l, k), mul(goal_r, k)
    return goal_l, goal_r
