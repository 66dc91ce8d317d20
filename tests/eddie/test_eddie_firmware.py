"""Golden vectors for the Eddie board model (wcdrive.eddie.firmware): every command
of the seed's Tables 1-4, their errors, the two's-complement edges, line endings and
the 254-character limit. Each expected reply was worked out by hand from Parallax's
Spin source (docs/eddie.md), not by running the model."""

from __future__ import annotations

import itertools

import pytest

from wcdrive.eddie import firmware as fw
from wcdrive.eddie.board import EddieLoop
from wcdrive.eddie.firmware import EddieFirmware


def run(lines: list[bytes], board: EddieFirmware | None = None) -> list[bytes]:
    board = board or EddieFirmware()
    return [board.feed(line) for line in lines]


# (commands sent before, the command, its reply)
VECTORS: list[tuple[list[bytes], bytes, bytes]] = [
    # Table 1: interface
    ([], b"HWVER\r", b"0001\r"),
    ([], b"VER\r", b"000C\r"),
    ([], b"ver\r", b"000C\r"),
    ([], b"VER 1\r", b"ERROR\r"),
    ([], b"VERB 1\r", b"\r"),
    ([], b"VERB 0\r", b"\r"),
    ([], b"VERB 2\r", b"ERROR\r"),
    ([], b"VERB\r", b"ERROR\r"),
    ([b"VERB 1\r"], b"VERB 2\r", b"ERROR - Invalid parameter\r"),
    ([b"VERB 1\r"], b"VERB\r", b"ERROR - Too few parameters\r"),
    ([b"VERB 1\r"], b"VERB 1 1\r", b"ERROR - Too many parameters\r"),
    ([b"VERB 1\r"], b"NOPE\r", b"ERROR - Invalid command\r"),
    ([b"VERB 1\r", b"VERB 0\r"], b"NOPE\r", b"ERROR\r"),
    ([], b"WATCH 0\r", b"\r"),
    ([], b"WATCH 1A\r", b"\r"),
    ([], b"WATCH 1B\r", b"ERROR\r"),
    ([], b"BLNK 10 5\r", b"\r"),
    ([], b"BLNK 10\r", b"ERROR\r"),
    ([], b"BLINK 10 5\r", b"ERROR\r"),           # the table's spelling: not in the source
    # Table 2: I/O on the GPIO mask (pins 16..18 at start)
    ([], b"INS\r", b"00070000\r"),
    ([], b"OUTS\r", b"00000000\r"),
    ([b"OUT 7FFFF\r"], b"OUTS\r", b"00070000\r"),
    ([b"OUT 7FFFF\r"], b"INS\r", b"00000000\r"),
    ([b"OUT 7ffff\r", b"IN 30000\r"], b"OUTS\r", b"00040000\r"),
    ([b"OUT 70000\r", b"HIGH 10000\r"], b"HIGHS\r", b"00010000\r"),
    ([b"OUT 70000\r", b"HIGH 10000\r"], b"LOWS\r", b"00060000\r"),
    ([b"OUT 70000\r", b"HIGH 10000\r"], b"READ\r", b"00010000\r"),
    ([b"OUT 70000\r", b"HIGH 70000\r", b"LOW 20000\r"], b"HIGHS\r", b"00050000\r"),
    ([b"HIGH FFFFFFFF\r"], b"HIGHS\r", b"00070000\r"),   # inputs too: the source masks GPIO only
    ([], b"IN 1\r", b"\r"),
    ([], b"OUT 1\r", b"\r"),
    ([], b"HIGH 1\r", b"\r"),
    ([], b"LOW 1\r", b"\r"),
    ([], b"SGP 0\r", b"\r"),
    ([b"SGP 0\r"], b"INS\r", b"00000000\r"),
    ([], b"OUT\r", b"ERROR\r"),
    ([], b"OUT 123456789\r", b"ERROR\r"),          # nine digits
    ([], b"OUT 7G\r", b"ERROR\r"),
    ([], b"READ 1\r", b"ERROR\r"),
    # Table 3: sensors (inputs: PING pin 0 sees 1.0 m, ADC channel 1 = FFF, 2 = 001)
    ([], b"PING\r", b"38F 000 000 000\r"),
    ([], b"ADC\r", b"000 FFF 001 000 000 000 000 000\r"),
    ([b"SPNG 3\r"], b"PING\r", b"38F 000\r"),
    ([b"SGP 7FFFF\r"], b"PING\r", b"\r"),           # every PING))) pin made GPIO
    ([b"SGP 7FFFF\r"], b"INS\r", b"0007FFFF\r"),
    ([b"SGP FFFFFFFF\r"], b"INS\r", b"0007FFFF\r"),
    ([b"SPNG 1\r"], b"PING\r", b"38F\r"),
    ([], b"PING 1\r", b"ERROR\r"),
    ([], b"SPNG\r", b"ERROR\r"),
    # Table 4: motion replies and errors
    ([], b"GO 7F 7F\r", b"\r"),
    ([], b"GO 80 80\r", b"\r"),
    ([], b"GO 1\r", b"ERROR\r"),
    ([], b"GOSPD 8000 7FFF\r", b"\r"),
    ([], b"GOSPD ffffff9c 64\r", b"\r"),
    ([], b"GOSPD 1 2 3\r", b"ERROR\r"),
    ([], b"STOP 0\r", b"\r"),
    ([], b"STOP FFFF\r", b"\r"),
    ([], b"STOP\r", b"ERROR\r"),
    ([], b"TRVL 7FFF 7F\r", b"\r"),
    ([], b"TRVL 10 80\r", b"ERROR\r"),              # speed 1..7F only
    ([], b"TRVL 10 FF\r", b"ERROR\r"),              # the table's "or 1..FF": not in the source
    ([], b"TRVL 10 0\r", b"ERROR\r"),
    ([], b"TURN 168 10\r", b"\r"),
    ([], b"TURN 5A 0\r", b"ERROR\r"),
    ([], b"ACC 0\r", b"\r"),
    ([], b"ACC 1FF\r", b"\r"),
    ([], b"ACC 200\r", b"ERROR\r"),
    ([], b"ACC 80000000\r", b"ERROR\r"),
    ([], b"SPD\r", b"0000 0000\r"),
    ([], b"HEAD\r", b"000\r"),
    ([], b"DIST\r", b"00000000 00000000\r"),
    ([], b"RST\r", b"\r"),
    ([], b"RST 0\r", b"ERROR\r"),
    ([], b"DIST 0\r", b"ERROR\r"),
    # the parser
    ([], b"dist\r", b"00000000 00000000\r"),
    ([], b"Dist\t\r", b"00000000 00000000\r"),
    ([], b" DIST\r", b"ERROR\r"),                  # a leading space: an empty command
    ([], b"DIX\x08ST\r", b"00000000 00000000\r"),   # backspace
    ([], b"\r", b""),                              # an empty line: no answer at all
]


@pytest.mark.parametrize(("before", "line", "reply"), VECTORS,
                         ids=[repr(v[1])[2:-3] + (f" after {len(v[0])}" if v[0] else "") for v in VECTORS])
def test_golden_vector(before: list[bytes], line: bytes, reply: bytes) -> None:
    board = EddieFirmware()
    board.inputs.ping_m = {0: 1.0, 1: None, 2: 3.5, 3: 0.005}
    board.inputs.adc = [0, 0xFFF, 1, 0, 0, 0, 0, 0]
    for b in before:
        assert not board.feed(b).startswith(b"ERROR"), b
    assert board.feed(line) == reply


def test_two_complement_parameters_set_the_state_the_source_computes() -> None:
    board = EddieFirmware()
    board.feed(b"GOSPD 8000 7FFF\r")
    assert [w.set_velocity for w in board.wheels] == [-32768, 32767]
    assert board.mode_name == "VELOCITY"
    board.feed(b"GOSPD FFFFFF9C ff9c\r")            # 32-bit and 16-bit -100
    assert [w.set_velocity for w in board.wheels] == [-100, -100]
    board.feed(b"GOSPD 80000000 18000\r")           # low words: 0 and -32768
    assert [w.set_velocity for w in board.wheels] == [0, -32768]
    board.feed(b"GO 80 7F\r")                       # -128 * 7520 / 127 truncates to -7579
    assert [w.set_power for w in board.wheels] == [-7579, 7520]
    assert board.mode_name == "POWER"
    board.feed(b"GO FFFFFF80 100\r")                # low bytes: -128 and 0
    assert [w.set_power for w in board.wheels] == [-7579, 0]
    board.feed(b"TRVL 8000 1\r")
    # InterpolateMidVariables: the left power -7579 / Kp 470 = -16, deadzone -> -15 ahead
    assert [w.set_position for w in board.wheels] == [-15 - 32768, -32768]
    board.feed(b"STOP 0\r")                         # power 0: no offset any more
    board.feed(b"TRVL 80000000 7F\r")               # low word 0: stay
    assert [w.set_position for w in board.wheels] == [0, 0]
    board.feed(b"TURN 7FFF 7F\r")                   # 32767 * 93 / 360 = 8464.8 -> 8464
    assert [w.set_position for w in board.wheels] == [8464, -8464]
    board.feed(b"TURN 8000 7F\r")                   # -8465.07 -> -8465
    assert [w.set_position for w in board.wheels] == [-8465, 8465]
    assert board.mode_name == "POSITION"
    board.feed(b"ACC 1FF\r")
    assert board.max_pos_accel == 511


def test_an_error_changes_nothing() -> None:
    board = EddieFirmware()
    board.feed(b"GOSPD 10 10\r")
    for line in (b"GOSPD 20 zz\r", b"GOSPD 20\r", b"TRVL 10 80\r", b"TURN 10 80\r", b"ACC 200\r",
                 b"GO 1 2 3\r", b"VERB 5\r", b"WATCH 20\r"):
        assert board.feed(line) == b"ERROR\r"
    assert board.mode_name == "VELOCITY"
    assert [w.set_velocity for w in board.wheels] == [16, 16]
    assert board.max_pos_accel == 200 and board.verbose == 0 and board.watch_s == 0


def test_dist_head_spd_fixed_width_twos_complement() -> None:
    board = EddieFirmware()
    board.tick(-5, 3)
    assert board.feed(b"DIST\r") == b"FFFFFFFB 00000003\r"
    # (L - R) = -8: (-8 // 186) * 360 / 186 = -15 (Spin keeps the sign): three digits of it
    assert board.feed(b"HEAD\r") == b"FF1\r"
    board.tick(95, -3)                              # L - R = 98 -> 189 degrees
    assert board.feed(b"HEAD\r") == b"0BD\r"
    board.tick(190, 0)                              # 190 // 186 = 4 -> 7 degrees
    assert board.feed(b"HEAD\r") == b"007\r"
    board.feed(b"RST\r")
    assert board.feed(b"DIST\r") == b"00000000 00000000\r"
    board.wheels[0].mot_pos_offset = -0x80000000 - 190
    board.wheels[1].mot_pos_offset = 0x7FFFFFFF
    assert board.feed(b"DIST\r") == b"80000000 7FFFFFFF\r"
    board = EddieFirmware()
    for k in range(1, 31):                          # left +1, right -1 a tick: 25 in 0.5 s
        board.tick(k, -k)
    assert board.feed(b"SPD\r") == b"0032 FFCE\r"


def test_line_endings_and_the_254_character_limit() -> None:
    # the source stores LF: a CR LF ending poisons the next command
    assert run([b"DIST\r\n", b"DIST\r"]) == [b"00000000 00000000\r", b"ERROR\r"]
    assert run([b"DIST\n"]) == [b""]
    tolerant = EddieFirmware(eol="tolerant")
    assert run([b"DIST\r\n", b"DIST\r", b"VER\n", b"VER\r\n\r\n"], tolerant) == [
        b"00000000 00000000\r", b"00000000 00000000\r", b"000C\r", b"000C\r"]
    ok = b"DIST" + b" " * 249 + b"\r"               # 254 characters with the CR
    assert len(ok) == 254 and run([ok]) == [b"00000000 00000000\r"]
    long = b"DIST" + b" " * 250 + b"\r"             # 255: an error, given at the next CR
    board = EddieFirmware()
    assert board.feed(long) == b""
    assert board.feed(b"VER\r") == b"ERROR\r"       # ... and that line is lost
    assert board.feed(b"VER\r") == b"000C\r"
    board.feed(b"VERB 1\r")
    assert board.feed(b"X" * 300 + b"\r") == b"ERROR - Overflow\r"


def test_ping_range_limits() -> None:
    board = EddieFirmware()
    board.inputs.ping_m = {0: 0.0198, 1: 0.0193, 2: 3.1831, 3: 3.1842}   # 18, 17, 2900, 2901 units
    assert board.feed(b"PING\r") == b"012 000 B54 000\r"


def test_watch_stops_the_motors_after_silence() -> None:
    board = EddieFirmware()
    board.feed(b"WATCH 1\r")
    board.feed(b"GOSPD 20 20\r")
    for _ in range(50):                             # 1.0 s: not yet
        board.tick(0, 0)
    assert board.mode_name == "VELOCITY"
    board.tick(0, 0)
    assert board.mode_name == "POWER" and [w.set_power for w in board.wheels] == [0, 0]


def test_acc_ramp_trvl_and_turn_on_the_plant() -> None:
    loop = EddieLoop()
    loop.send(b"ACC 32\rGOSPD 28 28\r")             # 50 positions/s^2 toward 40 positions/s
    loop.run_until(0.1)
    mids = []
    for _ in range(10):
        loop.run_until(loop.time + 0.02)
        mids.append(loop.firmware.wheels[0].mid_velocity)
    steps = {b - a for a, b in itertools.pairwise(mids)}
    assert steps == {1}                             # 50 / 50 Hz: one position/s per iteration
    loop.run_until(3.0)
    assert 38 <= loop.firmware.wheels[0].motor_speed <= 42
    loop.send(b"STOP 0\rRST\rACC C8\rTRVL 48 20\r")  # 72 positions = 2 revolutions
    loop.run_until(8.0)
    left, right = loop.firmware.distance()
    assert abs(left - 72) <= 2 and abs(right - 72) <= 2
    loop.send(b"RST\rTURN 5A 10\r")                 # 90 degrees: 23 positions each way
    loop.run_until(12.0)
    left, right = loop.firmware.distance()
    assert abs(left - 23) <= 2 and abs(right + 23) <= 2
    loop.send(b"HEAD\r")
    loop.run_until(12.1)
    head = int(loop.take_output()[-1][1][:3], 16)
    assert 85 <= head <= 95


def test_spin_arithmetic() -> None:
    assert fw.sdiv(-7, 2) == -3 and fw.smod(-7, 3) == -1 and fw.smod(7, -3) == 1
    assert fw.sx8(0x180) == -128 and fw.sx16(0xFFFF9C) == -100
    assert fw.ssqrt(-1) == 65535 and fw.hexw(-15, 3) == b"FF1"


def test_deadzone_as_written_biases_a_zero_error_forward() -> None:
    # PDIteration: "elseif Difference =< DEADZONE" takes every difference below 1,
    # so a wheel exactly on its set point gets +1 position of error: +Kp of power
    board = EddieFirmware()
    board.feed(b"GOSPD 0 0\r")
    assert board.tick(0, 0) == (470, 470)
    board.tick(0, 0)
    assert [w.set_power for w in board.wheels] == [470, 470]
    assert [w.motor_power for w in board.wheels] == [470, 470]


@pytest.mark.parametrize(("distance", "positions"), [(b"10", 16), (b"20", 32)])
def test_stop_slows_to_a_stop_over_the_distance(distance: bytes, positions: int) -> None:
    loop = EddieLoop()
    loop.send(b"GOSPD 1E 1E\r")                     # 30 positions/s
    loop.run_until(3.0)
    before = loop.firmware.distance()
    loop.send(b"STOP " + distance + b"\r")
    loop.run_until(8.0)
    after = loop.firmware.distance()
    assert [a - b for a, b in zip(after, before, strict=True)] == [positions, positions]
    assert abs(loop.plant.axle_velocity()[0]) < 1e-3


def test_ping_and_stop_0_answer_after_the_firmwares_waits() -> None:
    loop = EddieLoop()
    loop.run_until(0.1)
    loop.send(b"PING\rVER\r")
    loop.run_until(0.2)
    (t_ping, ping), (t_ver, ver) = loop.take_output()
    assert ping.count(b" ") == 3 and ver == b"000C\r"
    assert 0.025 <= t_ping - 0.1 < 0.028            # 5 bytes at 115200, then 25 ms
    assert t_ver >= t_ping                          # VER waits in the buffer behind PING
    loop.send(b"STOP 0\r")
    loop.run_until(0.3)
    ((t_stop, stop),) = loop.take_output()
    assert stop == b"\r" and 0.020 <= t_stop - 0.2 < 0.023
