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
    """The charger input pulled low for 40 ms, twice, the second a half period later in
    the tick grid's phase: 40 ms holds at most one tick, and one of the two holds one
    whatever the grid's phase, so a tick reads the input low (checked: else the test
    says nothing) and the debounce, two ticks, lets it go: no event, no stop."""
    serial = [(0.02, NEUTRAL), *every(FORWARD, 0.2, 1.2)]
    rec = _run(serial, [(0.600, 1, True), (0.640, 1, False), (0.825, 1, True), (0.865, 1, False)], 1.3)
    ticks = tick_states(rec)
    assert [t for t, after in ticks if after["inhibitTick"] & 1], "no tick read the glitch"
    assert board_lines(rec, b"EVT:INHIBIT") == []
    assert all(after["targetR"] == 3.0 and not after["inhibitStable"] for t, after in ticks if 0.4 < t < 1.2)


@pytest.mark.parametrize("cause", ["seat", "hot", "low battery"])
@pytest.mark.parametrize(("left", "right"), [(8.0, 4.0), (16.0, 8.0), (-4.0, 15.0), (14.0, -14.0),
                                             (-17.0, -11.0), (3.0, 2.0)])
def test_every_cap_keeps_the_curvature(cause: str, left: float, right: float) -> None:
    """On the port, by hand: the seat input (0.3 of ``max_wheel``), a winding at 117.5 deg C
    (the rollback half way: 0.75) and a supply at 21.25 V (half way to the cut-off:
    0.75) each scale both wheels' goals by one factor, so that the faster wheel is at
    its cap and the ratio of the two (the path's curvature) is what the profile's
    limits left of the host's; goals under the cap pass as they are."""
    from wcdrive.firmware.battery import battery_share
    from wcdrive.firmware.drive import drive_caps
    from wcdrive.firmware.inhibit import capped_goals, inhibit_share
    from wcdrive.firmware.state import FirmwareState
    from wcdrive.firmware.thermal import thermal_share

    s = FirmwareState(targetL=f32(left), targetR=f32(right), supplyVolts=f32(24.0))
    if cause == "seat":
        s.inhibitStable = 2
    elif cause == "hot":
        s.windingTempL = f32(117.5)
    else:
        s.supplyVolts = f32(21.25)
    share = min(inhibit_share(s), thermal_share(s), battery_share(s))
    assert share == pytest.approx({"seat": 0.3, "hot": 0.75, "low battery": 0.75}[cause], abs=1e-6)
    cap = float(mul(s.maxWheel, share))
    base_l, base_r = drive_caps(s, s.targetL, s.targetR)        # the profile's limits first
    goal_l, goal_r = capped_goals(s)
    if max(abs(base_l), abs(base_r)) <= cap:
        assert (goal_l, goal_r) == (base_l, base_r)
    else:
        assert max(abs(goal_l), abs(goal_r)) == pytest.approx(cap, rel=1e-6)
        assert goal_l / goal_r == pytest.approx(base_l / base_r, rel=1e-6)


@pytest.mark.simavr
def test_the_seat_input_keeps_a_curve_on_both_backends() -> None:
    """The seat raised at 0.6 s while the host asks for a curve, the left wheel at 8 rad/s
    and the right at 4: the setpoints settle at 5.28 and 2.64 rad/s, the curve kept."""
    serial = [(0.02, NEUTRAL), *every(b"rp04.00,lp08.00,\n", 0.2, 1.5)]
    rec = recorded(Trace(duration=1.6, serial=_framed(serial), inhibits=[(0.6, 2, True)],
                         encoders={"left": turning(1.6, True, 5.2), "right": turning(1.6, False, 2.6)}))
    cap = float(mul(f32(C.MAX_WHEEL_SPEED), C.INHIBIT_2_SPEED))
    settled = [after for t, after in tick_states(rec) if 1.3 <= t < 1.55]
    assert settled and all(a["setpointL"] == pytest.approx(cap, abs=1e-6)
                           and a["setpointR"] == pytest.approx(cap / 2, abs=1e-6) for a in settled)


def test_a_pulse_inside_one_tick_window_is_the_pin_that_tick_read() -> None:
    """An inhibit pulse that starts just after a tick's entry and ends before the next
    tick is read by that tick alone, and the lock step takes it: the comparison accepts
    any value the trace put on the pins between a tick's entry and the next event, not
    only the values at the two ends (a drawn trace whose pulse fell so, once the TX
    ring's growth moved the ticks 0.19 ms, failed ``wcdrive verify`` with "the trace's
    pins disagree")."""
    from wcdrive.boards.simavr.virtual_mega import F_CPU

    serial = [(0.02, NEUTRAL)]
    quiet = _run(serial, [], 1.0)
    entry = next(ev.cycle / F_CPU for ev in quiet.events if ev.kind == "tick" and ev.cycle / F_CPU > 0.5)
    rec = _run(serial, [(entry + 2e-6, 1, True), (entry + 0.02, 1, False)], 1.0)
    ticks = [ev for ev in rec.events if ev.kind == "tick"]
    seen = [ev for ev in ticks if int(ev.after["inhibitTick"]) & 1]
    assert [ev.cycle / F_CPU for ev in seen] == [entry]
