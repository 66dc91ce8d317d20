"""The table of drive profiles (docs/safety.md, "Drive profiles"): ``set:profile=<n>``
puts a row of the seven drive limits in force, ``set:`` of a limit changes the row in
force, ``save`` stores every row and the number, ``defaults`` gives the presets. On the
port alone against the spec's presets, and on both backends in lock step (the compiled
firmware in simavr, the port replaying it with no mismatch)."""

from __future__ import annotations

from itertools import pairwise

import pytest

from tests.support.recordings import board_lines, every, recorded, tick_states, turning
from wcdrive.firmware import constants as C
from wcdrive.firmware.eeprom import BLOCK_BYTES, DATA_BYTES, block_image, check, ee_crc
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.params import DRIVE_FIRST
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line
from wcdrive.protocol.spec import PROFILE_PARAMETERS, PROFILES

R = 0.1524
FIELDS = ("fwdSpeed", "revSpeed", "driveAccel", "driveDecel", "turnSpeed", "turnAccel", "turnAtSpeed",
          "tremorDamping")


def _limits(fw: Firmware) -> tuple[float, ...]:
    return tuple(round(getattr(fw.state, f), 4) for f in FIELDS)


def test_the_presets_are_the_specs_and_profile_0_limits_nothing() -> None:
    """Four rows, named open, indoor, outdoor and attendant; the first is every limit's
    default, so a board that never selects a profile drives as before the table."""
    assert [p.name for p in PROFILES] == ["open", "indoor", "outdoor", "attendant"]
    assert len(PROFILES) == C.PROFILE_COUNT == C.PROFILE_MAX + 1
    assert PROFILE_PARAMETERS == ("fwd_speed", "rev_speed", "drive_accel", "drive_decel",
                                  "turn_speed", "turn_accel", "turn_at_speed", "tremor_damping")
    fw = Firmware()
    assert fw.state.profile == 0
    assert _limits(fw) == (2.69, 2.69, 3.0, 3.0, 9.5, 40.0, 1.0, 0.0)
    assert PROFILES[1].values == (1.0, 0.5, 0.5, 0.6, 1.0, 2.0, 0.5, 0.0)


def say(fw: Firmware, command: bytes) -> bytes:
    """``command`` in a loop() pass of its own, a tick after it (the answers of a tick
    are three at most): what the board answered."""
    now = fw.state.lastControlTime
    out = fw.feed(command + b"\n")
    fw.tick((now + 50) & 0xFFFFFFFF, 0, 0)
    return out


def test_selecting_editing_and_restoring_profiles_on_the_port() -> None:
    fw = Firmware()
    assert say(fw, b"set:profile=1") == b"PAR:profile,1\r\n"
    assert _limits(fw) == (1.0, 0.5, 0.5, 0.6, 1.0, 2.0, 0.5, 0.0)
    say(fw, b"set:fwd_speed=1.25")                       # the row in force changes
    say(fw, b"set:profile=3")
    assert _limits(fw) == (0.6, 0.4, 0.4, 0.5, 0.8, 1.5, 0.8, 0.0)
    say(fw, b"set:profile=1")                            # selected again: the edit is there
    assert _limits(fw)[0] == 1.25 and _limits(fw)[1:] == (0.5, 0.5, 0.6, 1.0, 2.0, 0.5, 0.0)
    assert say(fw, b"set:profile=4") == b"ERR:range\r\n"
    assert say(fw, b"set:profile=x") == b"ERR:number\r\n"
    assert fw.state.profile == 1
    assert say(fw, b"get:profile") == b"PAR:profile,1\r\n"
    say(fw, b"defaults")                                 # the presets, profile 0
    assert fw.state.profile == 0 and _limits(fw)[0] == 2.69
    say(fw, b"set:profile=1")
    assert _limits(fw)[0] == 1.0


def test_a_saved_table_and_profile_come_back_at_boot_on_the_port() -> None:
    """The EEPROM block holds every row and the number: an edited row not in force and
    the profile in force both come back; a row value out of its parameter's range
    makes the block ``range``."""
    image = block_image({"profile": 2, "fwdSpeed": 1.5})
    # docs/safety.md: layout 7, 176 bytes
    assert C.EEPROM_LAYOUT == 7 and BLOCK_BYTES == 176 and check(image[:BLOCK_BYTES]) is None
    fw = Firmware(eeprom=bytearray(image))
    assert fw.boot_output().endswith(b"EVT:PARAMS_LOADED\r\n")
    assert fw.state.profile == 2 and fw.state.fwdSpeed == 1.5
    fw.feed(b"set:profile=1\nset:turn_speed=0.5\nset:profile=3\nsave\n")
    while fw.state.eeBusy:
        fw.eeprom_ready()
    again = Firmware(eeprom=fw.state.eeprom)
    assert again.state.profile == 3 and _limits(again) == (0.6, 0.4, 0.4, 0.5, 0.8, 1.5, 0.8, 0.0)
    again.feed(b"set:profile=1\n")
    assert again.state.turnSpeed == 0.5
    again.feed(b"set:profile=2\n")
    assert again.state.fwdSpeed == 1.5
    bad = bytearray(block_image({"profile": 1}))
    assert check(bytes(bad[:BLOCK_BYTES])) is None
    bad[1 + 4 * DRIVE_FIRST + 4 * 7 * 3] = 0xFF            # row 3's fwd_speed: past 2.69
    bad[1 + 4 * DRIVE_FIRST + 4 * 7 * 3 + 3] = 0x7F
    bad[DATA_BYTES:DATA_BYTES + 2] = ee_crc(bytes(bad)).to_bytes(2, "little")
    assert check(bytes(bad[:BLOCK_BYTES])) == "range"


@pytest.mark.simavr
def test_a_profile_selected_caps_and_ramps_the_drive_on_both_backends() -> None:
    """hello:4, ``set:profile=1`` (indoor: 1.0 m/s forward, 0.5 m/s^2), then CMDVEL asks
    2 m/s: the setpoints climb 0.5 / 0.1524 x 0.05 = 0.164 rad/s a tick and stop at
    1.0 / 0.1524 = 6.562 rad/s; TLM's state says profile 1 (bits 8 and 9). Then
    ``set:profile=0`` mid-drive: the limits are the open profile's, the setpoints go on
    toward 2 m/s. Red with ``useProfile`` a no-op: the first drive reaches 2 m/s."""
    duration = 6.0
    serial = [(0.01, b"hello:4\n"), (0.02, frame(b"set:profile=1", 1)), (0.03, frame(b"x:0.000,t:0.000", 2))]
    writes = [*every(b"x:2.000,t:0.000", 0.2, 4.0), (4.0, b"set:profile=0"),
              *every(b"x:2.000,t:0.000", 4.05, duration - 0.1)]
    serial += [(t, frame(cmd, 3 + k)) for k, (t, cmd) in enumerate(writes)]
    wheels = {side: turning(duration, side == "left", 6.5) for side in ("left", "right")}
    rec = recorded(Trace(duration=duration, serial=serial, encoders=wheels))
    ticks = tick_states(rec)
    held = [a for t, a in ticks if 3.0 < t < 4.0]
    assert all(a["profile"] == 1 for a in held)
    assert all(a["setpointL"] == a["setpointR"] == pytest.approx(1.0 / R, rel=1e-5) for a in held)
    rising = [b["setpointR"] - a["setpointR"] for (_, a), (_, b) in pairwise(ticks)
              if 0.3 < b["setpointR"] < 6.0 and b["setpointR"] > a["setpointR"]]
    assert sorted(rising)[len(rising) // 2] == pytest.approx(0.5 / R * 0.05, rel=1e-4)
    states = [m for m in map(parse_line, board_lines(rec, b"TLM:")) if isinstance(m, ExtendedTelemetry)]
    assert states and {m.drive_profile for m in states[20:70]} == {1}
    assert states[-1].drive_profile == 0
    last = ticks[-1][1]
    assert last["profile"] == 0 and last["setpointR"] > 1.5 / R


@pytest.mark.simavr
def test_an_estop_under_a_slow_profile_stops_at_the_emergency_rate_on_both_backends() -> None:
    """Under the indoor profile (``drive_decel`` 0.5 m/s^2: 0.164 rad/s a tick), the
    chair at its 1.0 m/s (6.562 rad/s), then ``estop``: from the next tick the setpoints
    fall by ``estop_decel`` (15 rad/s^2: 0.75 rad/s a tick) to 0, the profile's slower
    ramp no part of it. Red with the profile's decel on the emergency ramp: 0.164 a
    tick, 40 ticks to stop."""
    duration = 4.0
    serial = [(0.01, b"hello:4\n"), (0.02, frame(b"set:profile=1", 1)), (0.03, frame(b"x:0.000,t:0.000", 2))]
    writes = [*every(b"x:1.000,t:0.000", 0.2, 3.0), (3.0, b"estop")]
    serial += [(t, frame(cmd, 3 + k)) for k, (t, cmd) in enumerate(writes)]
    wheels = {side: turning(duration, side == "left", 6.5) for side in ("left", "right")}
    rec = recorded(Trace(duration=duration, serial=serial, encoders=wheels))
    ticks = tick_states(rec)
    assert board_lines(rec, b"EVT:ESTOP") == [b"EVT:ESTOP"]
    k = next(i for i, (t, a) in enumerate(ticks) if t > 3.0 and a["emergencyStop"])
    before = ticks[k - 1][1]
    assert before["profile"] == 1 and before["setpointR"] == pytest.approx(1.0 / R, rel=1e-5)
    step = 15.0 * 0.05
    assert ticks[k][1]["estopDecel"] == 15.0
    level = before["setpointR"]
    for _, a in ticks[k:]:
        level = max(0.0, level - step)
        assert a["setpointL"] == a["setpointR"] == pytest.approx(level, abs=1e-5)
        assert a["targetL"] == a["targetR"] == 0.0
    assert level == 0.0 and k + 9 <= len(ticks)


@pytest.mark.simavr
def test_a_slower_profile_selected_on_the_move_slows_along_its_own_decel() -> None:
    """The open profile at 2 m/s (13.12 rad/s), then ``set:profile=1`` (indoor: 1.0 m/s,
    ``drive_decel`` 0.6 m/s^2) on the move: from the next tick the setpoints fall by
    0.6 / 0.1524 x 0.05 = 0.197 rad/s a tick (not the open profile's ramp, ``max_accel``
    5 rad/s^2: 0.25 a tick) and settle at 6.562 rad/s, no event, no fault."""
    fw = Firmware()
    fw.feed(b"set:profile=1\n")
    assert fw.state.driveDecel == pytest.approx(0.6) and fw.state.fwdSpeed == pytest.approx(1.0)
    duration = 6.5
    serial = [(0.01, b"hello:4\n"), (0.02, frame(b"x:0.000,t:0.000", 1))]
    writes = [*every(b"x:2.000,t:0.000", 0.2, 3.5), (3.5, b"set:profile=1"),
              *every(b"x:2.000,t:0.000", 3.55, duration - 0.1)]
    serial += [(t, frame(cmd, 2 + k)) for k, (t, cmd) in enumerate(writes)]
    wheels = {side: turning(duration, side == "left", 13.0) for side in ("left", "right")}
    rec = recorded(Trace(duration=duration, serial=serial, encoders=wheels))
    ticks = tick_states(rec)
    assert board_lines(rec, b"EVT:") == [b"EVT:PARAMS_DEFAULT,blank"]
    k = next(i for i, (t, a) in enumerate(ticks) if a["profile"] == 1)
    assert ticks[k - 1][1]["setpointR"] == pytest.approx(2.0 / R, rel=1e-5)
    falls = [a["setpointR"] - b["setpointR"] for (_, a), (_, b) in pairwise(ticks[k - 1:])
             if b["setpointR"] > 1.0 / R + 1e-4]
    # each tick's fall within 3 % (the ramp works in the chair's m/s and rad/s: binary32
    # rounding of the wheels' share), their mean the decel's
    step = 0.6 / R * 0.05
    assert len(falls) >= 30 and all(f == pytest.approx(step, rel=0.03) for f in falls)
    assert sum(falls) / len(falls) == pytest.approx(step, rel=1e-3)
    assert ticks[-1][1]["setpointR"] == pytest.approx(1.0 / R, rel=1e-5)
    assert all(a["faultFlags"] == 0 for _, a in ticks)
