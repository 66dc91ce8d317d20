"""The drive limits on both backends (docs/safety.md, "Drive limits"): set with
``set:`` and applied on each command path (WHEEL, CMDVEL, PPM) by the compiled firmware
in simavr, replayed on the port in lock step with no mismatch.
tests/firmware/test_drive_limits.py holds the same rules to figures worked by hand."""

from __future__ import annotations

from itertools import pairwise

import pytest

from tests.support.recordings import every, recorded, tick_states, turning
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import frame

pytestmark = pytest.mark.simavr

R = 0.1524


def _drive(settings: tuple[bytes, ...], command: bytes, duration: float,
           speed: float | tuple[float, float]) -> Recording:
    """``hello:4``, the ``set:`` commands ``settings``, a neutral command, then ``command``
    every 0.1 s from 0.2 s, framed, while the wheels turn at ``speed`` rad/s (forward
    positive; a pair: left, right)."""
    speeds = speed if isinstance(speed, tuple) else (speed, speed)
    first = [*settings, b"x:0.000,t:0.000"]
    writes = [*((0.02 + 0.01 * k, cmd) for k, cmd in enumerate(first)), *every(command, 0.2, duration - 0.1)]
    serial = [(0.01, b"hello:4\n")] + [(t, frame(cmd, k + 1)) for k, (t, cmd) in enumerate(writes)]
    return recorded(Trace(duration=duration, serial=serial,
                          encoders={side: turning(duration, side == "left", v)
                                    for side, v in zip(("left", "right"), speeds, strict=True)}))


def _steps(ticks: list[tuple[float, dict]], name: str) -> list[float]:
    values = [a[name] for _, a in ticks]
    return [b - a for a, b in pairwise(values)]


def test_wheel_commands_ramp_at_drive_accel_to_fwd_speed() -> None:
    """fwd_speed 1.0 m/s and drive_accel 0.5 m/s^2; WHEEL asks 10 rad/s on both wheels:
    the setpoints climb 0.5 / 0.1524 = 3.28 rad/s^2 (0.164 rad/s a 50 ms tick;
    max_accel's would be 5) and stop at 1.0 / 0.1524 = 6.562 rad/s, the targets still 10."""
    rec = _drive((b"set:fwd_speed=1.0", b"set:drive_accel=0.5"), b"rp10.00,lp10.00", 4.0, 6.5)
    ticks = tick_states(rec)
    assert ticks[-1][1]["fwdSpeed"] == pytest.approx(1.0) and ticks[-1][1]["targetR"] == 10.0
    rising = [d for d in _steps(ticks, "setpointR") if d > 0.0]
    assert len(rising) > 30 and sorted(rising)[len(rising) // 2] == pytest.approx(0.5 / R * 0.05, rel=1e-4)
    assert max(rising) < 0.5 / R * 0.052            # a tick runs up to a ms late
    assert ticks[-1][1]["setpointL"] == ticks[-1][1]["setpointR"] == pytest.approx(1.0 / R, rel=1e-5)


def test_cmdvel_backward_and_turning_within_rev_speed_and_turn_speed() -> None:
    """rev_speed 0.3 m/s and turn_speed 0.5 rad/s; CMDVEL asks -1 m/s turning at
    2 rad/s: the chair's speed is held to -0.3 m/s and its turn to 0.5 rad/s, the wheels
    at (-0.3 -+ 0.5 x 0.285) / 0.1524."""
    rec = _drive((b"set:rev_speed=0.3", b"set:turn_speed=0.5"), b"x:-1.000,t:2.000", 4.0, -2.0)
    last = tick_states(rec)[-1][1]
    assert last["setpointL"] == pytest.approx((-0.3 - 0.5 * 0.285) / R, rel=1e-4)
    assert last["setpointR"] == pytest.approx((-0.3 + 0.5 * 0.285) / R, rel=1e-4)


def test_a_full_stick_is_held_to_fwd_speed_and_turns_less_at_speed() -> None:
    """fwd_speed 0.3 m/s, turn_speed 1 rad/s, turn_at_speed 0.5; PPM's sticks full
    forward and full right (the left wheel at 5 rad/s, the right at 0: 0.38 m/s turning
    at 1.34 rad/s): the speed held to 0.3 m/s, at the top, where half the turn limit is
    left: 0.5 rad/s."""
    rec = _drive((b"set:fwd_speed=0.3", b"set:turn_speed=1.0", b"set:turn_at_speed=0.5"),
                 b"ppm:1500,2000,1500,2000,1500,1500,1500,1500", 4.0, (2.9, 1.0))
    last = tick_states(rec)[-1][1]
    assert (last["targetL"], last["targetR"]) == (5.0, 0.0)
    speed = (last["setpointL"] + last["setpointR"]) / 2 * R
    turn = (last["setpointR"] - last["setpointL"]) * R / 0.57
    assert speed == pytest.approx(0.3, rel=1e-4) and turn == pytest.approx(-0.5, rel=1e-4)
