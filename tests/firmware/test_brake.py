"""The parking brake the firmware owns (``brake_fitted`` 1; docs/safety.md, "The parking
brake"): engaged at rest with the motors then unpowered, released under the hold, its
coil watched through the brake driver's status pin.

Every trace runs on the compiled firmware in simavr, its status pin driven by the trace
(input 3), and is replayed on the port in lock step (0 mismatches, the tick's pin reads
checked against the trace), so each behaviour holds on both. The wheels stand still
(no encoder edges) unless a test says otherwise. tests/sim/test_brake_plant.py watches
the chair.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tests.support.recordings import COUNTS_PER_RAD, board_lines, every, recorded, tick_states
from wcdrive.firmware import constants as C
from wcdrive.firmware.brake import (
    BRAKE_ENGAGED,
    BRAKE_ENGAGING,
    BRAKE_PRELOAD,
    BRAKE_RELEASED,
    BRAKE_RELEASING,
    FAULT_BRAKE_OPEN,
    FAULT_BRAKE_SHORT,
)
from wcdrive.firmware.eeprom import block_image
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import edges_from_trajectory

pytestmark = pytest.mark.simavr

NEUTRAL = b"x:0.000,t:0.000,\n"
SLOW = b"rp01.00,lp01.00,\n"            # 1 rad/s each
FITTED = b"set:brake_fitted=1\n"


def _run(serial: list[tuple[float, bytes]], duration: float, status: list[tuple[float, int, bool]] = (),
         turning_from: float | None = None, turning_until: float = np.inf,
         eeprom: bytes | None = None, speed: float = 1.0) -> Recording:
    """The trace: ``serial``, the brake driver's status changes (input 3), the wheels
    still, or from ``turning_from`` s to ``turning_until`` s at ``speed`` rad/s (the left
    counting backwards)."""
    encoders = {}
    if turning_from is not None:
        t = np.linspace(0.0, duration, 4000)
        angle = (np.clip(t, turning_from, turning_until) - turning_from) * speed
        encoders = {side: edges_from_trajectory(t, 0.5 + (-1 if side == "left" else 1) * angle
                                                * COUNTS_PER_RAD)
                    for side in ("left", "right")}
    return recorded(Trace(duration=duration, serial=sorted(serial, key=lambda w: w[0]),
                          inhibits=list(status), encoders=encoders, eeprom=eeprom))


def _phases(ticks: list[tuple[float, dict]]) -> list[tuple[int, int, int]]:
    """(brakePhase, brakeReleased, parked) of each tick."""
    return [(a["brakePhase"], a["brakeReleased"], a["parked"]) for _, a in ticks]


def test_without_a_brake_fitted_the_pin_follows_the_pid_as_before() -> None:
    """brake_fitted 0 (the default): the pin is HIGH exactly while the chair is not
    parked, the phase never moves, and the parked chair's hold is what it was."""
    rec = _run([(0.02, NEUTRAL), *every(SLOW, 0.2, 0.9), (0.9, NEUTRAL)], 1.6, turning_from=0.25)
    ticks = tick_states(rec)
    assert all(a["brakeFitted"] == 0 and a["brakePhase"] == BRAKE_ENGAGED for _, a in ticks)
    assert all(a["brakeReleased"] == (0 if a["parked"] or a["faultFlags"] else 1) for _, a in ticks)
    assert any(a["brakeReleased"] for _, a in ticks)


def test_the_brake_engages_at_rest_and_then_unpowers_the_motors() -> None:
    """Fitted while parked from boot, the brake engages (its pin was LOW from reset) and
    after BRAKE_ENGAGE_TICKS the parked chair's motors are at duty 0, although the
    wheels rolled 32 counts off the hold's reference into the brake (beyond its
    deadband): the hold no longer drives against the brake."""
    rec = _run([(0.02, FITTED), (0.03, NEUTRAL)], 0.6, turning_from=0.06, turning_until=0.08)
    ticks = tick_states(rec)
    fitted = next(k for k, (_, a) in enumerate(ticks) if a["brakeFitted"])
    phases = [p for p, _, _ in _phases(ticks)[fitted:]]
    assert phases[:C.BRAKE_ENGAGE_TICKS] == [BRAKE_ENGAGING] * (C.BRAKE_ENGAGE_TICKS - 1) + [BRAKE_ENGAGED]
    engaged = [a for _, a in ticks[fitted:] if a["brakePhase"] == BRAKE_ENGAGED]
    assert len(engaged) >= 5
    assert all(abs(a["encTickR"] - a["holdRefR"]) > C.HOLD_DEADBAND_COUNTS for a in engaged)
    assert all(a["pwmL"] == 0 and a["pwmR"] == 0 and a["parked"] and not a["brakeReleased"] for a in engaged)


def test_a_motion_command_preloads_the_hold_then_releases_then_ramps() -> None:
    """Parked on the engaged brake, a motion command: one tick of the hold with the pin
    still LOW (BRAKE_PRELOAD), then the pin HIGH for BRAKE_RELEASE_TICKS with the chair
    still parked and the setpoints at zero, and only then the setpoints ramp. Stopped
    again, the pin goes LOW at the first parked tick and the motors are unpowered
    BRAKE_ENGAGE_TICKS later."""
    serial = [(0.02, FITTED), (0.03, NEUTRAL), *every(SLOW, 0.5, 1.2), (1.2, NEUTRAL)]
    rec = _run(serial, 2.2, turning_from=0.75, turning_until=1.4)
    ticks = tick_states(rec)
    asked = next(k for k, (_, a) in enumerate(ticks) if a["targetL"] != 0.0)
    seq = _phases(ticks)[asked:asked + 1 + C.BRAKE_PRELOAD_TICKS + C.BRAKE_RELEASE_TICKS]
    assert seq[0] == (BRAKE_PRELOAD, 0, 1)
    assert seq[C.BRAKE_PRELOAD_TICKS:C.BRAKE_PRELOAD_TICKS + C.BRAKE_RELEASE_TICKS - 1] == \
        [(BRAKE_RELEASING, 1, 1)] * (C.BRAKE_RELEASE_TICKS - 1)
    assert seq[-1] == (BRAKE_RELEASED, 1, 0)
    waiting = [a for _, a in ticks[asked:asked + C.BRAKE_PRELOAD_TICKS + C.BRAKE_RELEASE_TICKS]]
    assert all(a["setpointL"] == 0.0 and a["setpointR"] == 0.0 for a in waiting)
    assert ticks[asked + C.BRAKE_PRELOAD_TICKS + C.BRAKE_RELEASE_TICKS + 1][1]["setpointR"] > 0.0
    # stopped: engaged at the first parked tick, unpowered after the engage time
    parked = next(k for k, (t, a) in enumerate(ticks) if t > 1.2 and a["parked"])
    assert ticks[parked][1]["brakePhase"] == BRAKE_ENGAGING and not ticks[parked][1]["brakeReleased"]
    settled = ticks[parked + C.BRAKE_ENGAGE_TICKS][1]
    assert settled["brakePhase"] == BRAKE_ENGAGED
    assert all(a["pwmL"] == 0 and a["pwmR"] == 0 for _, a in ticks[parked + C.BRAKE_ENGAGE_TICKS:])
    assert all(a["faultFlags"] == 0 for _, a in ticks)


def test_an_open_coil_latches_with_the_brake_engaged_and_a_glitch_does_not() -> None:
    """The status LOW for one tick (a glitch) does nothing; LOW for BRAKE_STATUS_TICKS
    ticks with the brake engaged is ``EVT:FAULT,BRAKE_OPEN``; motion is refused, the
    motors are powered again (the brake may not hold: the wheels pushed 80 counts on
    are held), and ``reset`` with the coil still open latches it again."""
    serial = [(0.02, FITTED), (0.03, NEUTRAL), (1.0, SLOW), (1.3, b"reset\n"), (1.35, NEUTRAL)]
    status = [(0.3, 3, True), (0.33, 3, False), (0.6, 3, True)]
    rec = _run(serial, 1.8, status=status, turning_from=0.9, turning_until=0.95)
    ticks = tick_states(rec)
    held = [a for t, a in ticks if 1.0 < t < 1.3]
    assert held and all(a["holding"] and a["brakePhase"] == BRAKE_ENGAGED for a in held)
    assert all(a["pwmL"] > 0 and a["pwmR"] > 0 for a in held)
    assert all(a["faultFlags"] == 0 for t, a in ticks if t < 0.6)
    first = next(t for t, a in ticks if a["faultFlags"])
    assert 0.6 + 0.05 * (C.BRAKE_STATUS_TICKS - 1) <= first <= 0.6 + 0.05 * C.BRAKE_STATUS_TICKS + 0.001
    assert all(a["faultFlags"] == FAULT_BRAKE_OPEN for t, a in ticks if first <= t < 1.3)
    assert board_lines(rec, b"EVT:FAULT,").count(b"EVT:FAULT,BRAKE_OPEN") == 2
    assert any(line.startswith(b"ERR:fault") for line in board_lines(rec, b"ERR:"))
    assert all(not a["brakeReleased"] for _, a in ticks)


def test_a_shorted_coil_latches_with_the_brake_released_and_the_chair_stops() -> None:
    """Driving at 4 rad/s (the pin HIGH), the status LOW for BRAKE_STATUS_TICKS ticks is
    ``EVT:FAULT,BRAKE_SHORT``: the pin goes LOW at once and the brake stops the wheels
    at once (faster than the emergency ramp, 0.75 rad/s a tick). From the fault on the
    PID only brakes (no duty forward while the wheels turn forward or stand: its
    setpoints held no farther than their speeds; without that rule it drove them forward
    against the brake while the ramp ran down), then the chair parks, its wheels still
    trusted."""
    serial = [(0.02, FITTED), (0.03, NEUTRAL), *every(b"rp04.00,lp04.00,\n", 0.3, 1.6)]
    rec = _run(serial, 1.8, status=[(1.0, 3, True)], turning_from=0.4, turning_until=1.1, speed=4.0)
    ticks = tick_states(rec)
    first = next(t for t, a in ticks if a["faultFlags"])
    assert first <= 1.0 + 0.05 * C.BRAKE_STATUS_TICKS + 0.001
    at = next(a for t, a in ticks if t == first)
    assert at["faultFlags"] == FAULT_BRAKE_SHORT and not at["brakeReleased"] and at["emergencyStop"]
    assert board_lines(rec, b"EVT:FAULT,") == [b"EVT:FAULT,BRAKE_SHORT"]
    after = [a for t, a in ticks if t >= first]
    assert all((a["pwmL"] == 0 or a["dirL"] == C.LOW) and (a["pwmR"] == 0 or a["dirR"] == C.LOW)
               for a in after)
    assert after[-1]["parked"] and after[-1]["setpointL"] == after[-1]["setpointR"] == 0.0


def test_the_status_counts_at_one_level_of_the_pin() -> None:
    """Two LOW reads of the status either side of the pin going HIGH (one in the hold's
    preload, the brake engaged; one as it lets go) are no coil fault: a change of the pin
    starts the count again (an open-load flag and a switching transient are not a
    short)."""
    # the drive asked from 0.525 s, mid-period: the tick that takes it, and the hold's
    # preload and release after it, do not depend on a ms of the tick grid's phase
    serial = [(0.02, FITTED), (0.03, NEUTRAL), *every(SLOW, 0.525, 1.2)]
    rec = _run(serial, 1.4, status=[(0.58, 3, True), (0.67, 3, False)], turning_from=0.7)
    ticks = tick_states(rec)
    # each read against the pin as the tick before left it
    reads = [(a["brakeStatusTick"], before["brakeReleased"])
             for (_, before), (t, a) in itertools.pairwise(ticks) if 0.55 < t < 0.7]
    assert (1, 0) in reads and (1, 1) in reads
    assert all(a["faultFlags"] == 0 for _, a in ticks)


def test_a_status_count_left_from_a_brake_unfitted_is_not_carried_over() -> None:
    """One LOW read with the brake fitted, ``brake_fitted`` 0, then 1 again and one more
    LOW read: no fault (the count starts again with the parameter), on the firmware and
    the port's C tick alike (the lock step holds them to each other)."""
    serial = [(0.02, FITTED), (0.03, NEUTRAL), (0.33, b"set:brake_fitted=0\n"), (0.5, FITTED)]
    status = [(0.28, 3, True), (0.32, 3, False), (0.58, 3, True), (0.62, 3, False)]
    rec = _run(serial, 0.9, status=status)
    ticks = tick_states(rec)
    assert sum(a["brakeStatusTick"] for _, a in ticks) == 2
    assert all(a["faultFlags"] == 0 for _, a in ticks)


def test_the_status_is_ignored_without_a_brake_fitted() -> None:
    """A board with no brake (brake_fitted 0) reads its status pin but never faults on it."""
    rec = _run([(0.02, NEUTRAL), *every(SLOW, 0.3, 1.0)], 1.2, status=[(0.1, 3, True)], turning_from=0.4)
    ticks = tick_states(rec)
    assert any(a["brakeStatusTick"] for _, a in ticks)
    assert all(a["faultFlags"] == 0 for _, a in ticks)


def test_brake_fitted_is_saved_and_loaded_and_out_of_range_refused() -> None:
    """``set:brake_fitted=2`` is ``ERR:range``; 1 is saved in the block (layout 3) and a
    board that boots from it has the brake fitted, engaged from reset (the motors at
    duty 0, the wheels rolled 32 counts into it); ``defaults`` leaves it fitted; a
    layout-2 block boots on the defaults."""
    rec = _run([(0.02, b"set:brake_fitted=2\n"), (0.05, b"get:brake_fitted\n")], 0.2)
    assert b"ERR:range" in rec.tx and b"PAR:brake_fitted,0" in rec.tx
    saved = block_image({"brakeFitted": 1})
    rec = _run([(0.03, NEUTRAL), (0.3, b"defaults\n")], 0.5, eeprom=saved, turning_from=0.06,
               turning_until=0.08)
    assert b"EVT:PARAMS_LOADED" in rec.tx
    ticks = tick_states(rec)
    assert all(a["brakeFitted"] == 1 and a["brakePhase"] == BRAKE_ENGAGED and a["pwmL"] == a["pwmR"] == 0
               for _, a in ticks)
    assert abs(ticks[-1][1]["encTickR"] - ticks[-1][1]["holdRefR"]) > C.HOLD_DEADBAND_COUNTS
    rec = _run([], 0.1, eeprom=block_image({"brakeFitted": 1}, layout=2))
    assert b"EVT:PARAMS_DEFAULT,version" in rec.tx
    assert all(a["brakeFitted"] == 0 for _, a in tick_states(rec))


def _profile(points: list[tuple[float, float]], duration: float) -> dict:
    """Both wheels at the piecewise-linear speeds ``points`` (s, rad/s) from rest (the
    left counting backwards)."""
    t = np.linspace(0.0, duration, 8000)
    speed = np.interp(t, [p[0] for p in points], [p[1] for p in points])
    angle = np.concatenate([[0.0], np.cumsum((speed[1:] + speed[:-1]) / 2 * np.diff(t))])
    return {side: edges_from_trajectory(t, 0.5 + (-1 if side == "left" else 1) * angle * COUNTS_PER_RAD)
            for side in ("left", "right")}


@pytest.mark.parametrize("fitted", [False, True], ids=["no-brake", "brake-fitted"])
def test_push_mode_refuses_driving_freewheels_the_motors_and_brakes_above_the_push_speed(
        fitted: bool) -> None:
    """The brake's manual-release lever pulled (input 4) at 0.3 s: after the debounce
    ``EVT:PUSH,1``, motion refused (``ERR:inhibit``), no hold. Pushed at 2 rad/s each
    wheel is at the duty its back-EMF takes (FAULT_EFFORT_EMF a rad/s of its filtered
    speed, truncated), DIR forward: no current, freewheeling; pushed past PUSH_SPEED, at
    duty 0 (shorted, braking). Let go at 1.6 s: ``EVT:PUSH,0`` and motion waits for
    neutral (``ERR:neutral``); no fault throughout. With or without a brake fitted (its
    phase does not unpower the freewheeling motors)."""
    serial = [(0.02, NEUTRAL), (0.6, SLOW), (1.7, SLOW)] + ([(0.01, FITTED)] if fitted else [])
    speeds = [(0.0, 0.0), (0.4, 0.0), (0.6, 2.0), (1.0, 2.0), (1.2, 6.0), (1.4, 6.0), (1.5, 0.0), (2.0, 0.0)]
    rec = recorded(Trace(duration=2.0, serial=sorted(serial), inhibits=[(0.3, 4, True), (1.6, 4, False)],
                         encoders=_profile(speeds, 2.0)))
    ticks = tick_states(rec)
    pushing = [(t, a) for t, a in ticks if a["inhibitStable"] & C.INHIBIT_PUSH]
    assert 0.3 + 0.05 <= pushing[0][0] <= 0.3 + 0.05 * C.INHIBIT_DEBOUNCE_TICKS + 0.001
    assert all(a["parked"] and not a["holding"] and a["targetL"] == 0.0 for _, a in pushing)
    slow = [a for t, a in pushing if 0.75 <= t <= 1.0]
    fast = [a for t, a in pushing if 1.25 <= t <= 1.4]
    assert slow and fast
    for a in slow:
        for side in ("L", "R"):
            v = a[f"filtVel{side}"]
            assert a[f"pwm{side}"] == int(np.float32(abs(v)) * np.float32(C.FAULT_EFFORT_EMF)) > 20
            assert a[f"dir{side}"] == C.HIGH
    assert all(a["filtVelL"] > C.PUSH_SPEED and a["pwmL"] == a["pwmR"] == 0 for a in fast)
    assert board_lines(rec, b"EVT:PUSH") == [b"EVT:PUSH,1", b"EVT:PUSH,0"]
    assert board_lines(rec, b"ERR:") == [b"ERR:inhibit", b"ERR:neutral"]
    after = [a for t, a in ticks if t > 1.75]
    assert after and all(a["needNeutral"] and a["targetL"] == 0.0 for a in after)
    assert all(a["faultFlags"] == 0 for _, a in ticks)
