"""The motors' heat (docs/safety.md, "Motor heat"): the firmware's estimate of each
winding from the effort it commands less the back-EMF of what it measures (it has no
current or temperature sensor), the rollback of the current limit and the top speed
past THERMAL_ROLLBACK_TEMP, and the cut-off fault at THERMAL_CUTOFF_TEMP.

The estimate is held to the first-order result worked out by hand, the rollback to its
bounds and to the equilibrium it settles at. On both backends (the compiled firmware in
simavr, replayed on the port in lock step with no mismatch), drives whose windings are
set hot at a tick's entry (``Trace.pokes``: a trace of seconds cannot heat a motor
whose time constant is 900 s). tests/sim/test_thermal_plant.py drives the plant.
"""

from __future__ import annotations

import math

import pytest

from tests.support.recordings import board_lines, every, recorded, tick_states, turning
from wcdrive.avr.f32 import f32
from wcdrive.firmware import constants as C
from wcdrive.firmware.motors import set_motor
from wcdrive.firmware.thermal import pid_bounds, rollback_of, winding_loss, winding_step
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line

#: W: the loss at the driver's current limit, worked by hand: 41 duty of effort is
#: 41 / 255 x 24 V / 0.3 ohm = 12.86 A, and 12.86^2 x 0.3 ohm = 49.6 W.
LIMIT_LOSS = 41.0**2 * (24.0 / 255.0) ** 2 / 0.3


def _run_estimate(temp: float, loss_of, seconds: float) -> float:
    t = f32(temp)
    for _ in range(round(seconds / 0.05)):
        t = winding_step(t, loss_of(t), f32(0.05))
    return t


# ---- the estimate against the hand-worked first-order result ---------------------------
def test_the_loss_is_the_effort_squared_within_the_current_limit() -> None:
    """Stalled at full duty, braking a wheel at speed with duty 0, or driving backward:
    the current limit's 49.6 W; freewheeling (the duty its back-EMF takes, THERMAL_EMF a rad/s), none."""
    assert winding_loss(255, C.HIGH, 0.0) == pytest.approx(LIMIT_LOSS, rel=1e-4)
    assert winding_loss(0, C.HIGH, 5.0) == pytest.approx(LIMIT_LOSS, rel=1e-4)
    assert winding_loss(100, C.LOW, -2.0) == pytest.approx(LIMIT_LOSS, rel=1e-4)
    assert winding_loss(28, C.HIGH, 2.0) == 0.0           # the motor's 14.0 duty a rad/s
    # half the current limit's effort: a quarter of its loss
    assert winding_loss(28 + 20, C.HIGH, 2.0) == pytest.approx(20.0**2 / 41.0**2 * LIMIT_LOSS, rel=1e-4)


def test_the_estimate_heats_and_cools_as_one_thermal_mass() -> None:
    """At the current limit from THERMAL_AMBIENT, after one time constant (R C = 2.5 K/W
    x 360 J/K = 900 s) the rise is 1 - 1/e of R x 49.6 W = 124.1 K: 78.4 K. With no
    current from 125 deg C, it falls to 1/e of its 100 K rise in the same time."""
    rise = 2.5 * LIMIT_LOSS
    heated = _run_estimate(C.THERMAL_AMBIENT, lambda t: winding_loss(255, C.HIGH, 0.0), 900.0)
    assert heated == pytest.approx(C.THERMAL_AMBIENT + rise * (1 - math.exp(-1.0)), abs=0.05)
    cooled = _run_estimate(125.0, lambda t: 0.0, 900.0)
    assert cooled == pytest.approx(C.THERMAL_AMBIENT + 100.0 * math.exp(-1.0), abs=0.05)


# ---- the rollback ----------------------------------------------------------------------
def test_the_rollback_lowers_the_driving_limit_and_leaves_braking_free() -> None:
    """Halfway from THERMAL_ROLLBACK_TEMP to THERMAL_CUTOFF_TEMP the effort limit is
    halfway from 41 to THERMAL_EFFORT_MIN (33 duty); an output that drives the way the
    wheel turns is held to the back-EMF's duty plus that, in percent of full duty; one
    that brakes is not held."""
    half = (C.THERMAL_ROLLBACK_TEMP + C.THERMAL_CUTOFF_TEMP) / 2
    assert rollback_of(C.THERMAL_ROLLBACK_TEMP) == 0.0 and rollback_of(half) == 0.5
    assert rollback_of(C.THERMAL_CUTOFF_TEMP) == rollback_of(200.0) == 1.0
    assert pid_bounds(C.THERMAL_ROLLBACK_TEMP, 2.0) == (-100.0, 100.0)
    lo, hi = pid_bounds(half, 2.0)
    assert lo == -100.0 and hi == pytest.approx((14.0 * 2.0 + 33.0) / 2.55, rel=1e-5)
    lo, hi = pid_bounds(half, -2.0)
    assert hi == 100.0 and lo == pytest.approx((-14.0 * 2.0 - 33.0) / 2.55, rel=1e-5)
    lo, hi = pid_bounds(C.THERMAL_CUTOFF_TEMP, 0.0)
    assert hi == -lo == pytest.approx(25.0 / 2.55, rel=1e-5)


def test_a_stalled_motor_at_its_rolled_back_limit_settles_short_of_the_cutoff() -> None:
    """A wheel held standing while the PID asks for all it may: the duty is the highest
    output ``pid_bounds`` allows at a standstill, as ``set_motor`` writes it. The estimate
    settles where the loss of the limit it sets is what it sheds, 25 + 2.5 x loss(cap(T))
    = T with cap(T) = 41 - 16 x rollback(T), solved here by bisection (115.6 deg C), and
    never latches the cut-off."""
    def duty(t: float) -> int:
        return set_motor(pid_bounds(t, 0.0)[1])[0]

    def excess(t: float) -> float:
        cap = 41.0 - rollback_of(t) * 16.0
        return 25.0 + 2.5 * cap**2 * (24.0 / 255.0) ** 2 / 0.3 - t

    a, b = C.THERMAL_ROLLBACK_TEMP, C.THERMAL_CUTOFF_TEMP
    for _ in range(60):
        m = (a + b) / 2
        a, b = (m, b) if excess(m) > 0 else (a, m)
    assert a == pytest.approx(115.6, abs=0.05)
    settled = _run_estimate(C.THERMAL_AMBIENT, lambda t: winding_loss(duty(t), C.HIGH, 0.0), 4 * 3600.0)
    # the duty is whole (set_motor truncates): a little under the bound, a little cooler
    assert a - 1.5 < settled <= a + 0.05 and settled < C.THERMAL_CUTOFF_TEMP - 5.0


# ---- on both backends ------------------------------------------------------------------
def _drive(command: bytes, duration: float, pokes: list[tuple[float, dict]], speed: float = 3.0) -> Recording:
    """``hello:4``, a neutral command, then ``command`` every 0.1 s, framed, while the
    wheels turn at ``speed`` rad/s (short of the command: the PID asks for more)."""
    writes = [(0.02, b"x:0.000,t:0.000"), *every(command, 0.2, duration - 0.1)]
    serial = [(0.01, b"hello:4\n")] + [(t, frame(cmd, k + 1)) for k, (t, cmd) in enumerate(writes)]
    return recorded(Trace(duration=duration, serial=serial, pokes=pokes,
                          encoders={side: turning(duration, side == "left", speed)
                                    for side in ("left", "right")}))



@pytest.mark.simavr
def test_a_hot_motor_rolls_back_its_current_limit_and_the_top_speed() -> None:
    """Driving with the PID saturated (the wheels at 3 rad/s, 15 rad/s asked), both
    windings set to 120 deg C at 3.0 s: ``EVT:THERMAL,1`` at that tick, TLM state bit 6;
    from then each duty is at most the back-EMF's plus the rolled-back limit (30.3 duty
    at 120 deg C, against 255 before) and the setpoints ramp down to two thirds of
    max_wheel. Set back to 60 deg C at 5.0 s: ``EVT:THERMAL,0``, and full duty again."""
    rec = _drive(b"rp15.00,lp15.00", 6.0, [(3.0, {"windingTempL": 120.0, "windingTempR": 120.0}),
                                           (5.0, {"windingTempL": 60.0, "windingTempR": 60.0})])
    ticks = tick_states(rec)
    before = [a for t, a in ticks if 2.7 <= t < 3.0]
    hot = [a for t, a in ticks if 3.0 <= t < 5.0]
    after = [a for t, a in ticks if 5.0 <= t]
    assert before and all(a["pwmL"] == a["pwmR"] == 255 for a in before)
    assert board_lines(rec, b"EVT:THERMAL") == [b"EVT:THERMAL,1", b"EVT:THERMAL,0"]
    k = rollback_of(f32(120.0))
    for a in hot:
        assert a["thermalRollback"] == 1
        for side in ("L", "R"):
            limit = 14.0 * a["filtVel" + side] + 41.0 - 16.0 * k
            assert a["pwm" + side] <= limit + 1, (a["pwm" + side], limit)
    assert min(a["pwmL"] for a in hot[1:]) >= 14.0 * 3.0 + 30.0 - 3     # at the limit, not below it
    last = hot[-1]                      # its estimate a little below 120 by now: its own share
    share_cap = C.MAX_WHEEL_SPEED * (1 - 0.5 * rollback_of(max(last["windingTempL"], last["windingTempR"])))
    assert last["setpointL"] == last["setpointR"] == pytest.approx(share_cap, rel=1e-5)
    # full duty again (until the scripted wheels, short of the setpoint at full duty,
    # read as stalled on a grade: EVT:STALLED_ON_GRADE near the trace's end)
    assert after[0]["thermalRollback"] == 0 and any(a["pwmL"] == a["pwmR"] == 255 for a in after)
    tlm = [parse_line(line) for line in board_lines(rec, b"TLM:")]     # as a host reads them
    assert all(isinstance(m, ExtendedTelemetry) for m in tlm)
    hot_seen = [m.thermal_rollback for m in tlm if isinstance(m, ExtendedTelemetry)]
    assert any(hot_seen) and not hot_seen[-1]


@pytest.mark.simavr
def test_the_cutoff_latches_its_fault_and_stops_the_chair() -> None:
    """The left winding set to 125.5 deg C at 1.0 s while driving: ``EVT:FAULT,OVERHEAT_L``
    at that tick, the e-stop ramp, then motion refused (``NAK:<seq>,fault``)."""
    rec = _drive(b"rp03.00,lp03.00", 2.5, [(1.0, {"windingTempL": 125.5, "windingTempR": 80.0})])
    ticks = tick_states(rec)
    assert board_lines(rec, b"EVT:FAULT,") == [b"EVT:FAULT,OVERHEAT_L"]
    latched = next(t for t, a in ticks if a["faultFlags"])
    assert 1.0 <= latched <= 1.06
    at = next(a for t, a in ticks if t == latched)
    assert at["faultFlags"] == 0x800 and at["emergencyStop"] and at["targetL"] == at["targetR"] == 0.0
    assert board_lines(rec, b"NAK:") and all(line.endswith(b",fault") for line in board_lines(rec, b"NAK:"))
    last = parse_line(board_lines(rec, b"TLM:")[-1])
    assert isinstance(last, ExtendedTelemetry) and last.fault_names == ("OVERHEAT_L",)


@pytest.mark.simavr
def test_the_rollback_keeps_its_band_brakes_freely_and_both_cutoffs_latch() -> None:
    """Driving at 3 rad/s with 1 rad/s asked (the PID brakes), the left winding set to
    107 deg C (below the start, the rollback off: nothing), then 111 (``EVT:THERMAL,1``),
    107 (within the 5 K band: still on), 104 (``EVT:THERMAL,0``); while on, the
    outputs brake (negative, unbounded). Then both windings at 126 deg C: both cut-off
    faults in one tick."""
    rec = _drive(b"rp01.00,lp01.00", 4.0, [
        (0.8, {"windingTempL": 107.0}), (1.2, {"windingTempL": 111.0}), (1.8, {"windingTempL": 107.0}),
        (2.4, {"windingTempL": 104.0}), (2.8, {"windingTempL": 126.0, "windingTempR": 126.0})])
    ticks = tick_states(rec)
    on = [t for t, a in ticks if a["thermalRollback"] and t < 2.8]
    assert on and 1.2 <= on[0] < 1.26 and 2.4 <= on[-1] + 0.05 < 2.46
    # (and on again at the cut-off's 126)
    assert board_lines(rec, b"EVT:THERMAL") == [b"EVT:THERMAL,1", b"EVT:THERMAL,0", b"EVT:THERMAL,1"]
    braking = [a for t, a in ticks if a["thermalRollback"] and not a["faultFlags"]]
    assert braking and all(a["dirL"] == C.LOW and a["pwmL"] > 0 for a in braking[2:])
    assert board_lines(rec, b"EVT:FAULT,")[:2] == [b"EVT:FAULT,OVERHEAT_L", b"EVT:FAULT,OVERHEAT_R"]
    latched = [a for t, a in ticks if t >= 2.8]
    assert latched[0]["faultFlags"] == 0x1800


def test_a_reset_of_a_winding_still_at_the_cutoff_latches_it_again() -> None:
    """On the port: a latched ``OVERHEAT_R`` whose winding is still at 125 deg C; the
    chair parked, ``reset`` clears the fault and the next tick latches it again."""
    from wcdrive.firmware.final_control import Firmware

    fw = Firmware(boot_millis=0)
    fw.state.windingTempR = f32(126.0)
    out = fw.tick(50, 0, 0)
    assert b"EVT:FAULT,OVERHEAT_R" in out and fw.state.faultFlags == 0x1000
    for k in range(2, 6):
        fw.tick(50 * k, 0, 0)
    fw.feed(b"reset\n")
    assert fw.state.faultFlags == 0
    assert b"EVT:FAULT,OVERHEAT_R" in fw.tick(300, 0, 0) and fw.state.faultFlags == 0x1000


def _held_on_a_grade(duration: float, pokes: list[tuple[float, dict]]) -> Recording:
    """``_drive`` of a neutral command, the wheels rolling back down a grade at 0.05
    rad/s (some 4 counts a tick) from 0.3 s: the chair parks at once and the hold pushes
    back against the drift."""
    return _drive(b"x:0.000,t:0.000", duration, pokes, speed=-0.05)


@pytest.mark.simavr
def test_a_hot_motor_holding_the_chair_on_a_grade_keeps_holding() -> None:
    """A chair without a brake held on a grade by its motors: the left winding set to
    111 deg C at 1.0 s (the rollback on), then 126 at 1.5 s (``OVERHEAT_L`` latched).
    The hold's duties, tick by tick, are those of the same stand with the windings cold:
    the rollback lowers what the PID may ask for, not the hold's duty, and the cut-off
    latches its fault but the hold stays on (a hot motor rather than a rollaway)."""
    duration = 2.5
    cold = tick_states(_held_on_a_grade(duration, []))
    rec = _held_on_a_grade(duration, [(1.0, {"windingTempL": 111.0}), (1.5, {"windingTempL": 126.0})])
    hot = tick_states(rec)
    assert board_lines(rec, b"EVT:THERMAL") == [b"EVT:THERMAL,1"]
    assert board_lines(rec, b"EVT:FAULT,") == [b"EVT:FAULT,OVERHEAT_L"]
    assert [t for t, _ in hot] == [t for t, _ in cold]
    pushing = [(c, h) for (t, c), (_, h) in zip(cold, hot, strict=True) if t > 0.9]
    assert all(h["holding"] and h["pwmL"] > 0 and h["pwmR"] > 0 for _, h in pushing)
    assert [(h["pwmL"], h["dirL"], h["pwmR"], h["dirR"]) for _, h in pushing] == \
        [(c["pwmL"], c["dirL"], c["pwmR"], c["dirR"]) for c, _ in pushing]
    assert hot[-1][1]["faultFlags"] == 0x800 and hot[-1][1]["thermalRollback"]


def test_the_cutoff_comes_at_125_deg_c() -> None:
    """On the port, a parked chair (no loss, the winding cooling 0.0056 K a tick): a
    winding the tick's estimate leaves at 124.994 deg C latches nothing, one it leaves at
    125.004 ``OVERHEAT_R``: the cut-off is THERMAL_CUTOFF_TEMP, bracketed."""
    from wcdrive.firmware.final_control import Firmware

    for before, fault in ((125.0, 0), (125.01, 0x1000)):
        fw = Firmware(boot_millis=0)
        fw.state.windingTempR = f32(before)
        fw.tick(50, 0, 0)
        after = fw.state.windingTempR
        assert (after >= C.THERMAL_CUTOFF_TEMP) == bool(fault) and abs(after - 125.0) < 0.01
        assert fw.state.faultFlags == fault
