"""A healthy chair that is told to turn on the spot while it still rolls forward must not
latch ``ENC_REVERSED``: the wheel whose setpoint reverses lags the ramp, so for a few
ticks its setpoint is past -FAULT_REVERSE_SPEED while it still turns forward faster than
FAULT_REVERSE_SPEED. What tells that wheel from one whose encoder is wired backwards is
that it is slowing toward its setpoint (FAULT_REVERSE_APPROACH); a reversed encoder shows
the wheel moving away from the setpoint, or not closer (tests/firmware/test_fault_detection.py,
tests/sim/test_fault_injection.py, tests/firmware/test_fault_mutants.py keep those detected).

This is what latched ``EVT:FAULT,ENC_REVERSED_R`` at the end of corridor_closed with a 1 m
lookahead (commit 57ec0bc): pure pursuit asked for a turn on the spot (0, -0.6 rad/s)
within 0.2 m of the goal while the chair still rolled at about 0.5 m/s.
"""

from __future__ import annotations

import pytest

from tests.support.recordings import board_lines, every, recorded, tick_states, turning
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.firmware import constants as C
from wcdrive.firmware.control import FAULT_REVERSED_L, WHEEL_OK, WHEEL_REVERSED, WHEEL_SUSPECT, check_wheel
from wcdrive.hil.traces import Trace
from wcdrive.plant import Gyro, Plant
from wcdrive.sim import runner
from wcdrive.sim.scenario import Scenario, load

#: Forward at ``v`` m/s for 3 s, then a turn on the spot at ``w`` rad/s (the right
#: wheel's target reverses); each tripped ENC_REVERSED_R on a healthy chair.
SPIN_FROM_MOTION = [(0.8, -0.6), (0.8, -2.0), (0.5, -3.0)]


def _scenario(tmp_path, v: float, w: float) -> Scenario:
    path = tmp_path / "spin_from_motion.toml"
    path.write_text(f'name = "spin_from_motion"\nhost_rate_hz = 10\nsettle_s = 1.0\n'
                    f"[[segment]]\ncmdvel = [{v}, 0.0]\nduration = 3.0\n"
                    f"[[segment]]\ncmdvel = [0.0, {w}]\nduration = 1.5\n")
    return load(str(path))


@pytest.mark.parametrize(("v", "w"), SPIN_FROM_MOTION)
def test_turning_on_the_spot_from_motion_latches_no_fault(tmp_path, v: float, w: float) -> None:
    """The right wheel measures forward, beyond FAULT_REVERSE_SPEED, while its setpoint
    is beyond -FAULT_REVERSE_SPEED for at least FAULT_REVERSE_TICKS ticks in a row (the
    case the old check took for a reversed encoder), and no fault latches."""
    scenario = _scenario(tmp_path, v, w)
    loop = PortLoop(Plant(scenario.params()), Gyro(scenario.params(), 0))
    for t, data in scenario.host_commands():
        if t < scenario.duration:
            loop.send(data, at=round(t * F_CPU))
    run = longest = 0

    def on_tick(_: float) -> None:
        nonlocal run, longest
        s = loop.fw.state
        lagging = s.setpointR <= -C.FAULT_REVERSE_SPEED and s.filtVelR >= C.FAULT_REVERSE_SPEED
        run = run + 1 if lagging else 0
        longest = max(longest, run)

    loop.run_until(round(scenario.duration * F_CPU), on_tick)
    out = b"".join(data for _, data in loop.take_output())
    assert longest >= C.FAULT_REVERSE_TICKS           # the old check's condition held
    assert b"EVT:FAULT" not in out and loop.fw.state.faultFlags == 0
    assert loop.fw.state.reverseTicksR == 0


@pytest.mark.simavr
def test_turning_on_the_spot_from_motion_on_the_firmware(tmp_path) -> None:
    """The same on the compiled sketch in simavr, the port replaying it: no fault, 0
    differences."""
    result = runner.run(_scenario(tmp_path, *SPIN_FROM_MOTION[1]), backend="simavr")
    assert not any("EVT:FAULT" in line for _, line in result.link.events), result.link.events
    assert result.firmware_differences == 0


def _check(measured: float, previous: float, setpoint: float = -2.0, ticks: int = 0,
           direction: int | None = None) -> tuple[int, int]:
    """One wheel's check, the wheel driven at duty 40 toward its setpoint unless
    ``direction`` says otherwise."""
    if direction is None:
        direction = C.HIGH if setpoint > 0.0 else C.LOW
    verdict, _, reverse_ticks, _, _ = check_wheel(40, 0, 0, 40, direction, setpoint, measured, 0.0, 0, False,
                                                  0, ticks, 0, (0, 0.0, 0.0, 0), previous, False)
    return verdict, reverse_ticks


def test_a_wheel_slowing_toward_its_setpoint_is_not_counted() -> None:
    """Against the setpoint, beyond FAULT_REVERSE_SPEED both: not counted while the
    wheel came FAULT_REVERSE_APPROACH or more closer to the setpoint since the PID last
    ran (either sign of setpoint); counted, and reversed at FAULT_REVERSE_TICKS, while
    it holds its speed or moves away."""
    step = C.FAULT_REVERSE_APPROACH
    assert _check(1.5, 1.5 + step) == (WHEEL_OK, 0)
    assert _check(-1.5, -1.5 - step, setpoint=2.0) == (WHEEL_OK, 0)
    assert _check(1.5, 1.5 + 0.5 * step) == (WHEEL_SUSPECT, 1)
    assert _check(1.5, 1.5) == (WHEEL_SUSPECT, 1)
    assert _check(1.6, 1.5) == (WHEEL_SUSPECT, 1)
    assert _check(-1.6, -1.5, setpoint=2.0) == (WHEEL_SUSPECT, 1)
    assert _check(1.5, 1.5, ticks=C.FAULT_REVERSE_TICKS - 1) == (WHEEL_REVERSED, C.FAULT_REVERSE_TICKS)
    # Approaching resets the count, as any tick that is not against does.
    assert _check(1.5, 1.5 + step, ticks=C.FAULT_REVERSE_TICKS - 1) == (WHEEL_OK, 0)


def test_a_wheel_driven_the_way_it_reads_is_not_counted() -> None:
    """A wheel whose duty still drives it the way it turns (its PID's integral from the
    way it went, before the setpoint's reversal overcame it) reads what it is driven to
    do: not counted, not suspect (its PID runs, and brakes it), however long it lasts. A
    reversed encoder reads against the way its wheel is driven. This is what latched
    ENC_REVERSED on a spin asked on a grade at the chair's limit
    (tests/sim/test_thermal_plant.py's path climb): the wheel held its forward duty while
    suspect, and so could not slow."""
    for setpoint, measured, way in ((-2.0, 1.6, C.HIGH), (2.0, -1.6, C.LOW)):
        assert _check(measured, measured, setpoint=setpoint, direction=way) == (WHEEL_OK, 0)
        assert _check(measured, measured, setpoint=setpoint, direction=way,
                      ticks=C.FAULT_REVERSE_TICKS - 1) == (WHEEL_OK, 0)
        opposite = C.LOW if way == C.HIGH else C.HIGH
        assert _check(measured, measured, setpoint=setpoint, direction=opposite) == (WHEEL_SUSPECT, 1)
    verdict, *_ = check_wheel(40, 0, 0, 0, C.HIGH, -2.0, 1.6, 0.0, 0, False, 0, 0, 0, (0, 0.0, 0.0, 0),
                              1.6, False)
    assert verdict == WHEEL_SUSPECT             # at duty 0 it is driven no way: counted


@pytest.mark.simavr
def test_a_reversing_wheel_still_driven_forward_counts_only_once_driven_back() -> None:
    """Lock step: both wheels at 2 rad/s, then at 1.0 s the left's target reverses
    (``rp02.00,ln02.00``) while its encoder reads on forward at 2 rad/s, its integral
    poked at 0.98 s to drive it forward on (as a climb leaves it): while its duty drives
    it forward its reverse count stays 0 past its setpoint's -1 rad/s, and it counts
    from the first tick its duty drives it back, ``ENC_REVERSED_L`` three ticks on (an
    encoder that reads forward while its wheel is driven back is a reversed one). Red
    without the exemption: the count runs while the duty is forward, and the suspect
    tick freezes it there."""
    duration = 2.5
    writes = [(0.02, b"rp0,lp0,\n"), *every(b"rp02.00,lp02.00\n", 0.2, 1.0),
              *every(b"rp02.00,ln02.00\n", 1.0, duration - 0.05)]
    encoders = {side: turning(duration, side == "left", 2.0) for side in ("left", "right")}
    rec = recorded(Trace(duration=duration, serial=sorted(writes), encoders=encoders,
                         pokes=[(0.98, {"integralL": 6.0})]))
    ticks = tick_states(rec)
    forward = [a for t, a in ticks if a["setpointL"] <= -C.FAULT_REVERSE_SPEED and a["faultFlags"] == 0
               and a["dirL"] == C.HIGH and a["pwmL"] > 0]
    assert len(forward) >= C.FAULT_REVERSE_TICKS
    assert all(a["reverseTicksL"] == 0 for a in forward)
    back = next(i for i, (t, a) in enumerate(ticks) if a["setpointL"] < 0.0 and a["dirL"] == C.LOW
                and a["pwmL"] > 0)
    assert [a["reverseTicksL"] for _, a in ticks[back + 1:back + 3]] == [1, 2]
    assert ticks[back + 3][1]["faultFlags"] == FAULT_REVERSED_L
    assert board_lines(rec, b"EVT:FAULT") == [b"EVT:FAULT,ENC_REVERSED_L"]
