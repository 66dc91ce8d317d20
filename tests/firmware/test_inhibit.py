"""The inhibit inputs (ISO 7176-14, inhibit while charging; docs/safety.md, "Inhibit
inputs"): two pins, active LOW, debounced over ``INHIBIT_DEBOUNCE_TICKS`` ticks. Input
1 (the charger) inhibits driving and latches until released and a ``reset``; input 2
(the seat raised) caps the wheels at ``INHIBIT_2_SPEED`` of ``max_wheel``. Each change
is an ``EVT:INHIBIT,<n>,<1|0>``; released, motion needs a neutral command first.

Every trace runs on the compiled firmware in simavr, its pins driven by the trace, and
is replayed on the port in lock step (0 mismatches, the tick's pin reads checked
against the trace), so each behaviour holds on both. The wheels turn as commanded (the
encoders follow a steady 3 rad/s), so no stall muddies what the firmware drives.
tests/sim/test_inhibit_plant.py watches the chair.
"""

from __future__ import annotations

import pytest

from tests.support.recordings import board_lines, every, recorded, tick_states, turning
from wcdrive.avr.f32 import f32, mul
from wcdrive.firmware import constants as C
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import frame

pytestmark = pytest.mark.simavr

NEUTRAL = b"x:0.000,t:0.000,\n"
FORWARD = b"rp03.00,lp03.00,\n"          # 3 rad/s each, under max_wheel
FAST = b"rp08.00,lp08.00,\n"             # 8 rad/s: above the seat input's cap


def _framed(serial: list[tuple[float, bytes]]) -> list[tuple[float, bytes]]:
    """After ``hello:4`` (TLM on), each command framed with its own sequence number."""
    ordered = sorted(serial, key=lambda w: w[0])
    return [(0.01, b"hello:4\n")] + [(t, frame(cmd.rstrip(b"\n"), k + 1))
                                     for k, (t, cmd) in enumerate(ordered)]


def _run(serial: list[tuple[float, bytes]], inhibits: list[tuple[float, int, bool]],
         duration: float, speed: float = 3.0) -> Recording:
    return recorded(Trace(duration=duration, serial=_framed(serial), inhibits=inhibits,
                          encoders={side: turning(duration, side == "left", speed)
                                    for side in ("left", "right")}))


def _first(ticks: list[tuple[float, dict]], when) -> float:
    return next(t for t, after in ticks if when(after))


def test_the_charger_input_stops_the_chair_along_the_normal_ramp_and_latches() -> None:
    """Driving at 3 rad/s, the charger connected at 0.6 s: from its second tick the
    targets are 0 and the setpoints fall at max_accel a tick (not the e-stop's rate);
    motion is refused (``NAK:<seq>,inhibit``) while it is in and after it is out, until a
    ``reset`` (it latches); then a neutral command, and the chair drives again. The
    TLM state says so (bit 2)."""
    serial = [(0.02, NEUTRAL), *every(FORWARD, 0.2, 1.5),
              (1.8, b"reset\n"), (1.9, NEUTRAL), *every(FORWARD, 2.1, 2.6)]
    rec = _run(serial, [(0.6, 1, True), (1.2, 1, False)], 2.7)
    ticks = tick_states(rec)
    engaged = _first(ticks, lambda a: a["inhibitStable"] & 1)
    debounce = 0.05 * C.INHIBIT_DEBOUNCE_TICKS
    assert 0.6 + debounce - 0.05 <= engaged <= 0.6 + debounce + 0.001
    at = [after for t, after in ticks if t >= engaged]
    assert at[0]["targetL"] == at[0]["targetR"] == 0.0 and not at[0]["emergencyStop"]
    step = float(mul(f32(C.MAX_ACCEL), f32(0.05)))
    falls = [at[k]["setpointR"] - at[k + 1]["setpointR"] for k in range(3)]
    assert all(abs(f - step) < 1e-3 for f in falls), falls
    assert any(line.endswith(b",inhibit") for line in board_lines(rec, b"NAK:"))
    assert board_lines(rec, b"EVT:INHIBIT") == [b"EVT:INHIBIT,1,1", b"EVT:INHIBIT,1,0"]
    # latched: released at 1.2 s, still refused until the reset at 1.8 s
    latched = [t for t, after in ticks if after["inhibitLatched"] & 1]
    assert min(latched) == engaged and 1.75 < max(latched) < 1.85
    tlm = board_lines(rec, b"TLM:")
    assert any(int(line.split(b",")[16]) & 4 for line in tlm)     # TLM's state field
    assert not any(after["targetR"] for t, after in ticks if engaged <= t < 2.0)
    assert any(after["targetR"] == 3.0 for t, after in ticks if 2.1 < t < 2.6)


def test_the_seat_input_caps_the_wheels_and_asks_for_neutral_when_released() -> None:
    """The seat raised at 0.6 s while the host asks 8 rad/s (the wheels turn at 5.2):
    the setpoints settle at INHIBIT_2_SPEED of max_wheel (5.28 rad/s), the targets as
    commanded; lowered at 1.4 s, the chair stops along the normal ramp, and each
    motion command is refused (``NAK:<seq>,neutral``) until a neutral command. TLM bit 3."""
    serial = [(0.02, NEUTRAL), *every(FAST, 0.2, 1.6),
              (1.75, NEUTRAL), *every(FAST, 1.9, 2.8)]
    rec = _run(serial, [(0.6, 2, True), (1.4, 2, False)], 2.9, speed=5.2)
    ticks = tick_states(rec)
    cap = float(mul(f32(C.MAX_WHEEL_SPEED), C.INHIBIT_2_SPEED))
    capped = [after for t, after in ticks if 1.3 <= t < 1.45]
    assert all(a["setpointR"] == pytest.approx(cap, abs=1e-6) and a["targetR"] == 8.0 for a in capped)
    assert board_lines(rec, b"EVT:INHIBIT") == [b"EVT:INHIBIT,2,1", b"EVT:INHIBIT,2,0"]
    naks = board_lines(rec, b"NAK:")
    assert any(n.endswith(b",neutral") for n in naks) and not any(n.endswith(b",inhibit") for n in naks)
    assert any(int(line.split(b",")[16]) & 8 for line in board_lines(rec, b"TLM:"))
    released = next(t for t, after in ticks if t > 1.4 and after["needNeutral"])
    assert all(after["targetR"] == 0.0 for t, after in ticks if released <= t < 1.75)
    assert any(after["setpointR"] > cap for t, after in ticks if 2.5 < t < 2.9)


def test_a_glitch_shorter_than_the_debounce_does_nothing() -> None:
    """The charger input pulled low for less than a tick, twice: no event, no stop."""
    serial = [(0.02, NEUTRAL), *every(FORWARD, 0.2, 1.2)]
    rec = _run(serial, [(0.61, 1, True), (0.64, 1, False), (0.81, 1, True), (0.84, 1, False)], 1.3)
    assert board_lines(rec, b"EVT:INHIBIT") == []
    assert all(after["targetR"] == 3.0 for t, after in tick_states(rec) if 0.4 < t < 1.2)
