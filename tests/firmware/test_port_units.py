"""Unit and property tests of the port's pieces that need no simulator, plus the
millis() model and the constants checked against the firmware."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.avr.f32 import f32
from wcdrive.avr.timer0 import Timer0, millis_after, overflows_until
from wcdrive.firmware import constants as C
from wcdrive.firmware.control import compute_pid
from wcdrive.firmware.drive import ramp_toward
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.quadrature import QuadratureDecoder
from wcdrive.firmware.state import FirmwareState
from wcdrive.plant.encoders import edges_from_trajectory

REPO = Path(__file__).resolve().parents[2]


@given(states=st.lists(st.integers(0, 3), max_size=400), start=st.integers(0, 3))
def test_bulk_decoding_equals_per_edge(states: list[int], start: int) -> None:
    one = QuadratureDecoder(last=start)
    for s in states:
        one.edge(s)
    bulk = QuadratureDecoder(last=start)
    bulk.bulk(np.array(states, dtype=np.int64))
    assert (one.count, one.illegal, one.last) == (bulk.count, bulk.illegal, bulk.last)


@given(points=st.lists(st.floats(-5000, 5000), min_size=2, max_size=20))
def test_edges_from_trajectory_track_position(points: list[float]) -> None:
    times = np.linspace(0.0, 1.0, len(points))
    train = edges_from_trajectory(times, np.array(points))
    decoder = QuadratureDecoder(last=int(np.asarray([0b11, 0b01, 0b00, 0b10])[train.start_count % 4]))
    decoder.count = train.start_count
    decoder.bulk(train.states)
    assert decoder.count == train.end_count == int(np.floor(points[-1]))
    assert decoder.illegal == 0
    assert np.all(np.diff(train.times) >= 0)


def test_millis_skips_like_the_mega() -> None:
    t = Timer0()
    seen = []
    for _ in range(1000):
        t.overflow()
        seen.append(t.millis)
    assert seen[-1] == 1024                      # 1000 overflows of 1.024 ms
    assert len(set(np.diff(seen))) == 2          # steps of 1 and, now and then, 2
    assert millis_after(1000) == 1024
    assert millis_after(overflows_until(50)) >= 50 > millis_after(overflows_until(50) - 1)


def test_millis_wraps() -> None:
    assert millis_after(10, start_millis=2**32 - 3) == 7


def test_ramp_reaches_10_rad_s_in_2_s() -> None:
    sp = 0.0
    ticks = 0
    while sp != f32(10.0):
        sp = ramp_toward(sp, f32(10.0), f32(C.MAX_ACCEL * f32(0.05)))
        ticks += 1
    assert ticks == 40


def test_pid_back_calculation_holds_output_at_the_limit() -> None:
    integral = 0.0
    for _ in range(200):
        out, integral = compute_pid(f32(12.0), 0.0, integral, 0.0, C.KP_R, C.KI_R, C.KD_R,
                                    f32(0.05))
    assert out == 100.0
    # Back-calculated: Kp*e + Ki*I == 100 (to rounding), so no windup beyond saturation.
    assert abs(C.KP_R * 12.0 + C.KI_R * integral - 100.0) < 1e-3
    # A P term beyond the limit on its own: the integral is held at 0, never wound
    # against the saturation.
    for _ in range(3):
        out, integral = compute_pid(f32(17.0), 0.0, integral, 0.0, C.KP_R, C.KI_R, C.KD_R,
                                    f32(0.05))
        assert out == 100.0 and integral == 0.0


def test_tick_due_every_50_ms_across_the_wrap() -> None:
    fw = Firmware(boot_millis=2**32 - 20)
    assert not fw.due(2**32 - 1)
    assert fw.due(30)


def test_state_is_plain_and_copyable() -> None:
    s = FirmwareState(targetL=1.5, mode=C.MODE_WHEEL)
    t = s.copy()
    t.targetL = 2.0
    assert s.targetL == 1.5 and t.as_dict()["targetL"] == 2.0


def test_stop_parks_with_integrators_reset() -> None:
    fw = Firmware(FirmwareState(targetL=0.0, targetR=0.0, setpointL=0.2, setpointR=0.2,
                                integralL=3.0, integralR=3.0, parked=0))
    for k in range(1, 6):
        fw.tick(50 * k, 0, 0)
    assert fw.state.parked and fw.state.integralL == 0.0 and fw.state.pwmL == 0




def _ready() -> Firmware:
    """A board just booted whose host sent its neutral command first, which stood
    NEUTRAL_TICKS ticks: it takes motion commands ("Neutral before motion")."""
    fw = Firmware()
    fw.tick(50, 0, 0)
    fw.feed(b"x:0.000,t:0.000,\n")
    fw.tick(100, 0, 0)
    fw.tick(150, 0, 0)
    assert fw.state.needNeutral == 0
    return fw


@pytest.mark.parametrize(("command", "right", "left"), [
    (b"x:0.5,t:0.2,", 3.65, 2.91), (b"x:0.5,t:0,", 3.28, 3.28), (b"x:0,t:0.5,", 0.935, -0.935),
])
def test_seed_kinematics(command: bytes, right: float, left: float) -> None:
    fw = _ready()
    fw.feed(command)
    assert fw.state.targetR == pytest.approx(right, abs=0.005)
    assert fw.state.targetL == pytest.approx(left, abs=0.005)


def test_cmdvel_beyond_the_wheel_limit_keeps_the_curvature() -> None:
    fw = _ready()
    fw.feed(b"x:2.6,t:1.0,")
    right, left = fw.state.targetR, fw.state.targetL
    assert max(abs(right), abs(left)) <= C.MAX_WHEEL_SPEED * (1 + 1e-6)
    assert right / left == pytest.approx((2.6 + 0.285) / (2.6 - 0.285), rel=1e-5)


@given(last=st.integers(0, 2**32 - 1), waited=st.integers(0, 2**32 - 1), later=st.integers(0, 200))
def test_due_after_is_due_solved_for_the_time(last: int, waited: int, later: int) -> None:
    """``Firmware.due_after(now)`` ms after ``now`` the tick is due, and not before
    (the event-driven port loop jumps there), across the 49-day wrap."""
    fw = Firmware(FirmwareState(lastControlTime=last))
    now = (last + waited) & 0xFFFFFFFF
    wait = fw.due_after(now)
    assert fw.due((now + wait) & 0xFFFFFFFF)
    assert wait == 0 or not fw.due((now + wait - 1) & 0xFFFFFFFF)
    if waited < 2**32 - 300:
        assert fw.due((now + wait + later) & 0xFFFFFFFF)
