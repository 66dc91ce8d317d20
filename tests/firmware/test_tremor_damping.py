"""The tremor damping (docs/safety.md, "Drive limits"): ``tremor_damping``, a drive limit
of each profile, low-passes the joystick (PPM) in the tick before the caps; a stop is
never damped and the host's paths are not damped. By hand on the port
(``damped_targets``), then on both backends in lock step."""

from __future__ import annotations

import math

import pytest

from tests.firmware.test_drive_profiles_table import say
from tests.support.recordings import recorded, tick_states, turning
from wcdrive.avr.f32 import f32
from wcdrive.firmware import constants as C
from wcdrive.firmware.drive import damped_targets
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.state import FirmwareState
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import frame


def _state(mode: int, damping: float, left: float, right: float) -> FirmwareState:
    s = FirmwareState()
    s.mode, s.tremorDamping, s.targetL, s.targetR = mode, f32(damping), f32(left), f32(right)
    return s


def test_a_step_of_the_stick_is_followed_by_the_filter_worked_by_hand() -> None:
    """PPM, damping 0.5: from rest a step to 2 rad/s gives 1, 1.5, 1.75, 1.875 (each
    tick half the way left: 2 (1 - 0.5^n)); at 0.9, 0.2, 0.38, 0.542 (2 (1 - 0.9^n))."""
    for damping, expected in ((0.5, (1.0, 1.5, 1.75, 1.875)), (0.9, (0.2, 0.38, 0.542))):
        s = _state(C.MODE_PPM, damping, 2.0, 2.0)
        got = [damped_targets(s)[0] for _ in expected]
        assert got == pytest.approx(expected, abs=1e-6)
        assert s.dampedL == s.dampedR


def test_a_stop_the_host_and_no_damping_are_the_targets_at_once() -> None:
    """The stick at neutral (both targets 0) is a stop: the goals are 0 at the first tick,
    whatever the damping was holding. WHEEL and CMDVEL are not damped; nor is PPM with
    tremor_damping 0 (the default): the goals are the targets, bit for bit."""
    s = _state(C.MODE_PPM, 0.9, 2.0, 1.0)
    for _ in range(5):
        damped_targets(s)
    assert 0.0 < s.dampedL < 2.0
    s.targetL = s.targetR = 0.0
    assert damped_targets(s) == (0.0, 0.0)
    for mode, damping in ((C.MODE_WHEEL, 0.9), (C.MODE_CMDVEL, 0.9), (C.MODE_PPM, 0.0)):
        s = _state(mode, damping, 1.7, -0.3)
        assert damped_targets(s) == (f32(1.7), f32(-0.3))


def test_a_5_hz_tremor_is_taken_down_to_what_the_filter_passes() -> None:
    """A 5 Hz tremor on a held deflection, sampled by the 20 Hz tick (+a, +a, -a, -a
    around the mean): the goals keep the mean and swing g / sqrt(1 + d^2) of it at the
    most (g = 1 - d: 7.4 % at d = 0.9, 15.6 % at 0.8, the fundamental's gain; the
    sequence is that sine, sqrt(2) a by pi/4)."""
    for damping in (0.8, 0.9):
        s = _state(C.MODE_PPM, damping, 0.0, 0.0)
        goals = []
        for k in range(200):
            s.targetL = s.targetR = f32(2.0 + (1.0 if k % 4 < 2 else -1.0))
            goals.append(damped_targets(s)[0])
        tail = goals[-40:]
        gain = (1 - damping) / math.sqrt(1 + damping ** 2)
        assert (max(tail) + min(tail)) / 2 == pytest.approx(2.0, abs=0.01)
        assert (max(tail) - min(tail)) / 2 <= gain * math.sqrt(2) * 1.0 + 1e-6
        assert (max(tail) - min(tail)) / 2 >= 0.9 * gain * 1.0       # the sampled peaks


def test_tremor_damping_is_a_drive_limit_of_the_profile() -> None:
    """0 by default, 0 to 0.9 (``ERR:range`` beyond); a row entry of the profile in force
    (selected again, it is back)."""
    fw = Firmware()
    assert fw.state.tremorDamping == 0.0
    for bad in (b"0.91", b"1"):
        assert fw.feed(b"set:tremor_damping=" + bad + b"\n") == b"ERR:range\r\n"
    assert say(fw, b"set:profile=1") == b"PAR:profile,1\r\n"
    assert say(fw, b"set:tremor_damping=0.6") == b"PAR:tremor_damping,0.6000\r\n"
    say(fw, b"set:profile=2")
    assert fw.state.tremorDamping == 0.0
    say(fw, b"set:profile=1")
    assert fw.state.tremorDamping == f32(0.6)


# ---- both backends --------------------------------------------------------------------------
def _stick(damping: float) -> Recording:
    """``hello:4``, ``set:tremor_damping``, neutral, then PPM: channel 2 at 1700 us
    (2 rad/s each wheel) shaken by +-100 us every 0.1 s (a 5 Hz tremor) from 0.2 to
    2.0 s, held at 1700 to 2.8 s, then neutral (1500) to 3.4 s."""
    duration = 3.4
    settings = [b"set:tremor_damping=%.1f" % damping, b"x:0.000,t:0.000"]
    writes = [(0.02 + 0.01 * k, cmd) for k, cmd in enumerate(settings)]
    for k in range(round((duration - 0.2) / 0.1)):
        t = round(0.2 + 0.1 * k, 4)
        ch2 = 1700 + (100 if k % 2 == 0 else -100) if t < 2.0 else (1700 if t < 2.8 else 1500)
        writes.append((t, b"ppm:1500,%d,1500,1500,1500,1500,1500,1500" % ch2))
    serial = [(0.01, b"hello:4\n")] + [(t, frame(cmd, k + 1)) for k, (t, cmd) in enumerate(writes)]
    encoders = {side: turning(duration, side == "left", 2.0) for side in ("left", "right")}
    return recorded(Trace(duration=duration, serial=serial, encoders=encoders))


@pytest.mark.simavr
def test_the_firmware_damps_a_shaken_stick_and_stops_at_once() -> None:
    """Lock step, the stick shaken at 5 Hz by +-1 rad/s around 2 rad/s: undamped the
    goals swing with the stick (2 rad/s peak to peak); at tremor_damping 0.8 they swing
    under a quarter of that around the same mean, and the setpoints with them. The stick
    held, the goals reach it; back at neutral, the goals are 0 at the first tick that
    reads it. Red with the damping taken out of the tick: the same swing as undamped."""
    swings = {}
    for damping in (0.0, 0.8):
        ticks = tick_states(_stick(damping))
        shaken = [a for t, a in ticks if 1.2 < t < 2.0]
        assert all(a["mode"] == C.MODE_PPM for a in shaken)
        goals = [a["dampedL"] for a in shaken]
        swings[damping] = (max(goals) - min(goals), (max(goals) + min(goals)) / 2,
                           max(a["setpointL"] for a in shaken) - min(a["setpointL"] for a in shaken))
        held = [a["dampedL"] for t, a in ticks if 2.6 < t < 2.8]
        assert held and all(g == pytest.approx(2.0, abs=0.02) for g in held)
        stopped = next(k for k, (t, a) in enumerate(ticks) if t > 2.8 and a["targetL"] == 0.0)
        assert ticks[stopped][1]["dampedL"] == 0.0
    (raw, raw_mean, raw_set), (damped, damped_mean, damped_set) = swings[0.0], swings[0.8]
    assert raw == pytest.approx(2.0, abs=0.05)
    assert damped < 0.25 * raw and damped_mean == pytest.approx(raw_mean, abs=0.05)
    assert damped_set < raw_set
