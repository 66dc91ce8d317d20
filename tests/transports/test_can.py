"""CAN: the frame mapping against the DBC (decoded by cantools), lossless round trips
through the gateway's conversions, and a gateway on python-can's virtual bus."""

from __future__ import annotations

import itertools
import struct
import time
from pathlib import Path

import can
import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.f32 import bits
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.params import PARAMS
from wcdrive.protocol import can_frames as cc
from wcdrive.protocol.codec import (
    PARAM_RANGES,
    ExtendedTelemetry,
    Feedback,
    LineDecoder,
    board_unframe,
    encode_cmdvel,
    encode_set,
    encode_wheel,
    frame,
    parse_line,
)
from wcdrive.transports.can_link import CanGateway, CanLink

DBC = cantools.database.load_file(Path(__file__).resolve().parents[2] / "protocol" / "wcdrive.dbc")
_channels = itertools.count()

linear = st.integers(-2680, 2680).map(lambda v: v / 1000)
angular = st.integers(-9400, 9400).map(lambda v: v / 1000)
wheel = st.integers(-17590, 17590).map(lambda v: v / 1000)
seqs = st.none() | st.integers(0, 65535)


def _decode(can_id: int, data: bytes) -> dict:
    return DBC.decode_message(can_id, data, decode_choices=False)


@given(linear, angular, seqs)
def test_cmdvel_frame_matches_the_dbc_and_reaches_the_board_unchanged(v, w, seq) -> None:
    line = encode_cmdvel(v, w) if seq is None else frame(encode_cmdvel(v, w), seq)
    [(can_id, data)] = cc.command_to_frames(line)
    fields = _decode(can_id, data)
    assert can_id == 0x300
    assert fields["linear"] == pytest.approx(v) and fields["angular"] == pytest.approx(w)
    assert fields["has_seq"] == (seq is not None) and (seq is None or fields["seq"] == seq)
    # The line the gateway writes makes the port do exactly what the host's line does.
    direct, via_can = Firmware(), Firmware()
    direct.feed(frame(encode_cmdvel(v, w), 0 if seq is None else seq))   # the gateway's seq 0
    via_can.feed(cc.frame_to_command(can_id, data))
    assert direct.state.as_dict() | {"rxCount": 0} == via_can.state.as_dict() | {"rxCount": 0}


@given(wheel, wheel, seqs)
def test_wheel_frame_matches_the_dbc(right, left, seq) -> None:
    line = encode_wheel(right, left) if seq is None else frame(encode_wheel(right, left), seq)
    [(can_id, data)] = cc.command_to_frames(line)
    fields = _decode(can_id, data)
    assert fields["right"] == pytest.approx(right) and fields["left"] == pytest.approx(left)
    fw = Firmware()
    fw.state.needNeutral = 0            # a board that drives: its neutral command confirmed
    fw.feed(cc.frame_to_command(can_id, data))
    expected = [strtod(b"%.3f" % abs(x))[0] * (1 if x >= 0 else -1) for x in (right, left)]
    assert [fw.state.targetR, fw.state.targetL] == expected


@given(st.sampled_from(sorted(PARAM_RANGES)), st.data(), seqs)
def test_param_set_reaches_the_board_as_the_same_binary32(name, data, seq) -> None:
    low, high = PARAM_RANGES[name]
    param = next(p for p in PARAMS if p.name == name)       # the table's order is not CAN's
    if param.integer:
        value = data.draw(st.integers(int(low), int(high)))
    else:
        value = data.draw(st.floats(low, high).map(lambda x: round(x, data.draw(st.integers(0, 7)))))
        value = min(max(value, low), high)
    line = encode_set(name, value)
    [(can_id, payload)] = cc.command_to_frames(line if seq is None else frame(line, seq))
    fields = _decode(can_id, payload)
    assert fields["op"] == 2 and fields["index"] == cc.PARAM_NAMES.index(name)
    direct, via_can = Firmware(), Firmware()
    direct.feed(line + b"\n")
    via_can.feed(cc.frame_to_command(can_id, payload))
    assert bits(getattr(direct.state, param.field)) == bits(getattr(via_can.state, param.field))


@given(st.integers(0, 10**12), st.integers(0, 12), st.integers(0, 3))
def test_board_text_round_trips_through_avr_strtod(mantissa, decimals, zeros) -> None:
    """Any value a host can set (avr strtod of its text) has a text the gateway finds."""
    digits = str(mantissa % 10**(decimals + 2)).rjust(decimals + 1, "0")
    text = (digits[:len(digits) - decimals] + "." + digits[len(digits) - decimals:] + "0" * zeros).encode()
    value = strtod(text)[0]
    assert bits(strtod(cc.board_text(value))[0]) == bits(value)


def test_control_frames() -> None:
    for word, op in ((b"hello", 1), (b"estop", 2), (b"reset", 3)):
        [(can_id, data)] = cc.command_to_frames(frame(word, 7))
        assert _decode(can_id, data) == {"op": op, "has_seq": 1, "seq": 7}
        assert cc.frame_to_command(can_id, data) == frame(word, 7)
    with pytest.raises(cc.CanCodecError, match="PPM"):
        cc.command_to_frames(b"ppm:1500,1500,1500,1500,1500,1500,1500,1500,")
    with pytest.raises(cc.CanCodecError, match="bad CRC"):
        cc.command_to_frames(b"$1:estop*0000\n")


def test_parameter_indices_keep_their_parameters() -> None:
    """WC_PARAM's indices 0 to 11 are the first table's, in its order; the drive limits,
    added to the serial table before watchdog_ms, take 12 to 18, the drive profile 19,
    stall_timeout, added after estop_decel, 20, and tremor_damping, added after
    turn_at_speed, 21 (protocol/CAN.md)."""
    assert cc.PARAM_NAMES == ("kp_l", "ki_l", "kd_l", "kp_r", "ki_r", "kd_r", "max_wheel", "max_accel",
                              "estop_decel", "watchdog_ms", "feedback_form", "brake_fitted", "fwd_speed",
                              "rev_speed", "drive_accel", "drive_decel", "turn_speed", "turn_accel",
                              "turn_at_speed", "profile", "stall_timeout", "tremor_damping")


u32 = st.integers(0, 2**32 - 1)
centi = st.integers(-30000, 30000).map(lambda c: cc._centi(c).encode())
enc_lines = st.builds(lambda a, b, vl, vr, m: b"ENC:%d,%d,VEL:%s,%s,MODE:%s" % (a, b, vl, vr, m),
                      st.integers(-2**31, 2**31 - 1), st.integers(-2**31, 2**31 - 1), centi, centi,
                      st.sampled_from([b"WHEEL", b"CMDVEL", b"PPM"]))
tlm_fields = st.tuples(u32, u32, st.integers(0, 65535), st.integers(0, 255), st.integers(0, 255),
                       st.integers(0, 1), st.integers(0, 1), u32, u32, st.integers(0, 255), u32, u32,
                       st.integers(0, 8191), st.integers(0, 0x3FFF), st.integers(0, 65535),
                       st.integers(0, 65535), st.integers(0, 1023))   # state: bits 8-9 the profile
# the supply (tenths of a volt), the 18th field; None: a board before it
supply_fields = st.one_of(st.none(), st.integers(0, 65535))
tlm_lines = st.builds(lambda v, dv: b"TLM:" + b",".join(b"%d" % x for x in v + (() if dv is None else (dv,))),
                      tlm_fields, supply_fields)
reasons = st.sampled_from([r.encode() for r in cc.REASONS[1:]])
reply_lines = st.one_of(
    st.builds(lambda s: b"ACK:%d" % s, st.integers(0, 65535)),
    st.builds(lambda s, r: b"NAK:%d,%s" % (s, r), st.integers(0, 65535), reasons),
    reasons.map(lambda r: b"ERR:" + r),
    st.sampled_from([b"EVT:" + e.encode() for e in cc.EVENTS[1:]]),
    st.sampled_from([b"HELLO:2,final_control", b"HELLO:3,final_control,3.0.0,2ce1a099",
                     b"HELLO:4,final_control,4.0.0,2ce1a099,3",
                     b"BOOT:final_control", b"PAR:kp_l,7.2000",
                     b"PAR:watchdog_ms,800", b"PAR:max_wheel,17.5900", b"PAR:ki_r,0.0100"]),
)
board_lines = st.one_of(enc_lines, tlm_lines, reply_lines)


@given(board_lines)
def test_board_lines_survive_the_bus_byte_for_byte(line) -> None:
    frames = cc.message_to_frames(parse_line(line))
    assembler = cc.TelemetryAssembler()
    text = b"".join(assembler.feed(can_id, data) for can_id, data in frames)
    assert text == line + b"\r\n"
    for can_id, data in frames:
        _decode(can_id, data)                     # every frame is one the DBC knows
    message = parse_line(line)
    if isinstance(message, Feedback):
        enc = _decode(*frames[0])
        assert (enc["count_left"], enc["count_right"]) == (message.count_left, message.count_right)
    if isinstance(message, ExtendedTelemetry):
        b = _decode(*frames[1])
        assert b["estop_latched"] == message.estop_latched and b["parked"] == message.parked
        assert b["pivot_phase"] == message.pivot_phase and b["free_ram"] == message.free_ram
        e = _decode(*frames[-1])
        assert (e["faults"], e["needs_neutral"], e["deflected"], e["drive_inhibited"], e["speed_capped"]) == (
            message.faults, message.needs_neutral, message.neutral_fault, message.drive_inhibited,
            message.speed_capped)
        assert (e["brake_applied"], e["push_mode"], e["thermal_rollback"], e["battery_low"]) == (
            message.brake_applied, message.push_mode, message.thermal_rollback, message.battery_low)
        if message.supply_dv is not None:
            f = _decode(*next(fr for fr in frames if fr[0] == cc.STATUS_F))
            assert f["supply"] == pytest.approx(message.supply_dv / 10.0)


@pytest.mark.parametrize("profile", range(4))
def test_the_hello_line_carries_the_profile_in_its_own_frame_before_the_reply(profile: int) -> None:
    """A board with drive profiles ends ``HELLO:`` with the profile in force: WC_HELLO_E
    (0x319), then the reply, which completes the line. A board before drive profiles
    sends the reply alone; a WC_HELLO_E that no HELLO reply follows names nothing."""
    line = b"HELLO:4,final_control,4.0.0,2ce1a099,%d" % profile
    frames = cc.message_to_frames(parse_line(line))
    assert [can_id for can_id, _ in frames] == [cc.HELLO_E, cc.REPLY]
    assert _decode(*frames[0]) == {"drive_profile": profile}
    assembler = cc.TelemetryAssembler()
    assert [assembler.feed(*f) for f in frames] == [b"", line + b"\r\n"]
    older = b"HELLO:4,final_control,4.0.0,2ce1a099"
    assert [can_id for can_id, _ in cc.message_to_frames(parse_line(older))] == [cc.REPLY]
    assert assembler.feed(*frames[0]) == b""
    assert assembler.feed(*cc.message_to_frames(parse_line(b"ACK:7"))[0]) == b"ACK:7\r\n"
    assert assembler.feed(*cc.message_to_frames(parse_line(older))[0]) == older + b"\r\n"


def test_a_status_without_its_last_frame_makes_no_line() -> None:
    """The TLM line is complete at WC_STATUS_E: the four frames before it alone, or a
    WC_STATUS_E after an incomplete set, make none; counters past 16 bits saturate."""
    line = b"TLM:1,2,3,4,5,1,0,6,7,128,8,9,100,256,70000,3,1"
    frames = cc.message_to_frames(parse_line(line))
    assembler = cc.TelemetryAssembler()
    assert b"".join(assembler.feed(i, d) for i, d in frames[:4]) == b""
    assert assembler.feed(*frames[4]) == b"TLM:1,2,3,4,5,1,0,6,7,128,8,9,100,256,65535,3,1\r\n"
    assert b"".join(assembler.feed(i, d) for i, d in frames[2:]) == b""


def test_gateway_on_the_virtual_bus_answers_with_the_hosts_sequence_number() -> None:
    channel = f"wc-can-{next(_channels)}"
    board = SimulatedBoard(speed=5).start()
    host = can.Bus(interface="virtual", channel=channel)
    with CanGateway(can.Bus(interface="virtual", channel=channel), board):
        try:
            host.send(can.Message(arbitration_id=0x302, data=struct.pack("<BBBBHH", 1, 0, 0, 1, 0, 501),
                                  is_extended_id=False))
            replies, feedback = [], 0
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and not (replies and feedback >= 5):
                msg = host.recv(0.2)
                if msg is None:
                    continue
                if msg.arbitration_id == 0x316:
                    replies.append(_decode(0x316, bytes(msg.data)))
                elif msg.arbitration_id == 0x311:
                    feedback += 1
            assert any(r["kind"] == 6 and r["code"] == 3 for r in replies)      # HELLO:3
            assert any(r["kind"] == 1 and r["seq"] == 501 for r in replies)       # ACK:501
            assert feedback >= 5
        finally:
            host.shutdown()
    board.close()


def test_line_decoder_reads_what_the_link_assembles() -> None:
    frames = cc.message_to_frames(parse_line(b"ENC:-5,7,VEL:-0.25,0.50,MODE:WHEEL"))
    assembler = cc.TelemetryAssembler()
    text = b"".join(assembler.feed(i, d) for i, d in frames)
    [msg] = LineDecoder().feed(text)
    assert msg == Feedback(-5, 7, -0.25, 0.5, "WHEEL")


def test_can_gateway_command_serves_a_host() -> None:
    """``wcdrive can-gateway --chair wcsim://...``, reached with ``connect("can://...")``."""
    import threading

    import wcdrive
    import wcdrive.transports.urlhandler.protocol_wcsim
    from wcdrive.tools.cli import main

    # Imported here first, not in both threads at once: under pytest every wcdrive module
    # is assertion-rewritten (ast.parse), and CPython 3.11.7's ast is not thread-safe
    # ("SystemError: AST constructor recursion depth mismatch" in the gateway's thread).
    channel = f"wc-cli-{next(_channels)}"
    gateway = threading.Thread(target=main, args=(["--debug", "can-gateway", "--chair", "wcsim://?speed=5",
                                                    "--interface", "virtual", "--channel", channel,
                                                    "--seconds", "5"],))
    gateway.start()
    try:
        with wcdrive.connect(f"can://virtual/{channel}") as chair:
            assert chair.protocol_version == 4
            assert chair.set_param("max_accel", 2.5) == 2.5
    finally:
        gateway.join()


def _lines_after(link: CanLink, marker: bytes, seconds: float = 10.0) -> list[bytes]:
    """The lines the link gives from the one that starts with ``marker`` on (a few)."""
    got, deadline = b"", time.monotonic() + seconds
    while time.monotonic() < deadline:
        got += link.read(4096, 0.1)
        lines = got.split(b"\r\n")[:-1]
        at = [i for i, line in enumerate(lines) if line.startswith(marker)]
        if at and len(lines) - at[0] >= 6:
            return lines[at[0]:]
    raise AssertionError(f"no {marker!r} line in {got[-300:]!r}")


def test_the_host_end_speaks_v4_frames_only_after_a_hello_4_as_the_board_does() -> None:
    """Plain lines before any hello; after ``hello:4`` the ``HELLO:4`` answer and every
    line after it framed, counting from 00 without a gap; plain again after the board
    resets (its ``BOOT:`` line) and after a plain ``hello`` (``HELLO:3``)."""
    channel = f"wc-can-{next(_channels)}"
    board = SimulatedBoard(speed=5).start()
    with CanGateway(can.Bus(interface="virtual", channel=channel), board):
        link = CanLink(can.Bus(interface="virtual", channel=channel))
        try:
            plain = _lines_after(link, b"ENC:")
            assert all(board_unframe(line) is None for line in plain), plain
            link.write(frame(b"hello:4", 1))
            framed = [board_unframe(line) for line in _lines_after(link, b"HELLO:4")]
            assert all(f is not None for f in framed), framed
            assert [f[1] for f in framed if f] == list(range(len(framed)))
            assert framed[0] and framed[0][0].startswith(b"HELLO:4,final_control,")
            board.dtr()                                 # the board resets
            after_boot = _lines_after(link, b"BOOT:")
            assert all(board_unframe(line) is None for line in after_boot), after_boot
            link.write(frame(b"hello:4", 2))
            _lines_after(link, b"HELLO:4")
            link.write(frame(b"hello", 3))
            v3 = _lines_after(link, b"HELLO:3")
            assert all(board_unframe(line) is None for line in v3), v3
        finally:
            link.close()
    board.close()
