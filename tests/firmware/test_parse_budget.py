"""Bounded parsing (item 5): no line may take more than 1 ms of AVR CPU to
parse, measured in cycles on the compiled firmware in simavr.

avr-libc's ``strtod`` scales by one float multiplication per 10^32 of exponent, so
``x:1e-31999,t:0,`` took 103,846 cycles (6.5 ms) and ``x:1e-31999,t:1e-31999,``
204,467 (12.8 ms) to parse before ``numberInReach`` (final_control.ino) refused such numbers;
meanwhile the 64-byte RX ring overflows. The rule (PROTOCOL.md, "Numbers"): at most
``NUMBER_MAX_DIGITS`` digits before the exponent (``ERR:number``) and at most
``NUMBER_MAX_EXP_DIGITS`` exponent digits (``ERR:range``).

What is measured, per line, from the entry of ``processByte`` for each of its bytes:

- **parse**: to the entry of ``answer`` (the reply's formatting) or, for a line that
  is not answered, to the next ``HardwareSerial::available`` (``loop()`` looking for
  the next byte). Framing, CRC, ``strtod``, the range checks, the kinematics and
  ``acceptCommand`` are all in it. At most ``PARSE_BUDGET`` (16,000 cycles, 1 ms).
- **whole**: to the next ``available``, the answer included. A framed ``set:``
  takes about 25,000 cycles with its answer (``PAR:`` through ``printFloat``, then
  ``ACK:``), whatever the number, so the whole line has a budget of its own,
  ``WHOLE_BUDGET`` (2 ms), far below the 63 bytes x ``UART_BYTE_CYCLES`` in which the
  RX ring fills.

The hypothesis search runs every line through the firmware and the port in lock step
(``wcdrive.hil.lockstep``: same replies, same state, bit for bit) and steers toward
the costliest lines (``hypothesis.target``). The worst line found is printed at the
end of the module.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, target
from hypothesis import strategies as st

from tests.conftest import thorough
from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.simavr.virtual_mega import F_CPU, Hit, VirtualMega, read_symbols
from wcdrive.firmware import constants as C
from wcdrive.firmware.commands import ParseError, number_in_reach, parse_number
from wcdrive.firmware.final_control import setup
from wcdrive.firmware.params import PARAMS
from wcdrive.hil.lockstep import Recorder, compare
from wcdrive.hil.traces import FIRST_COMMAND_S, Trace
from wcdrive.protocol.can_frames import board_text
from wcdrive.protocol.codec import (
    INTEGER_PARAMS,
    MAX_ANGULAR,
    MAX_LINEAR,
    MAX_WHEEL,
    PARAM_RANGES,
    encode_cmdvel,
    encode_set,
    encode_wheel,
    frame,
)

PARSE_BUDGET = 16_000                 # cycles: 1 ms at 16 MHz
WHOLE_BUDGET = 32_000                 # cycles: 2 ms, the answer included
RX_RING_FILL = 63 * UART_BYTE_CYCLES  # cycles until a 64-byte ring (63 usable) overflows
#: Where a byte's work ends: loop() back for the next byte (the next processByte or
#: rxGap), the tick after the bytes (controlTick), or the end of the pass (serialEventRun,
#: called once a loop() pass).
PASS_END = "_Z14serialEventRunv"
#: Lines apart by this much, so that no window of 50 ms has more than 3 to answer.
SPACING_S = 0.020
#: Each board first gets a neutral command, which has stood NEUTRAL_TICKS ticks by the
#: first line NEUTRAL_LEAD_S later, so a motion line is carried out (kinematics and
#: ``acceptCommand``, the costly path), not refused ("Neutral before motion").
NEUTRAL = b"x:0,t:0,\n"
NEUTRAL_LEAD_S = 0.12

#: About 70 ms an example (a fresh board in simavr and the port in lock step; 0.3 s on
#: two busy cores); the known costliest lines run at both depths
#: (``test_known_lines_within_budget``).
EXAMPLES = 1000 if thorough() else 20

#: The worst lines seen in this module: {"parse"|"whole": (cycles, line)}.
WORST: dict[str, tuple[int, bytes]] = {"parse": (0, b""), "whole": (0, b"")}


# ---- measuring -------------------------------------------------------------------
@pytest.fixture(scope="module")
def answer_symbol(elf: Path) -> str:
    """The ELF symbol of ``answer()`` (LTO adds a ``.lto_priv.N`` suffix)."""
    names = [n for n in read_symbols(elf)[1] if n.split(".")[0] == "_ZL6answer11ParseResultlh"]
    assert len(names) == 1, f"answer() is not one function in the ELF: {names}"
    return names[0]


@pytest.fixture(scope="module", autouse=True)
def _report_worst(request: pytest.FixtureRequest) -> Iterator[None]:
    yield
    plugins = request.config.pluginmanager
    reporter, capture = plugins.get_plugin("terminalreporter"), plugins.get_plugin("capturemanager")
    if reporter is None or capture is None or not WORST["whole"][0]:
        return
    with capture.global_and_fixture_disabled():
        reporter.write_line("")
        for kind, (cycles, line) in WORST.items():
            reporter.write_line(f"parse budget: worst {kind} {cycles} cycles "
                                f"({cycles / F_CPU * 1e3:.3f} ms) for {line!r}")


def line_costs(lines: list[bytes], elf: Path, answer_symbol: str) -> list[tuple[int, int]]:
    """Sends ``lines`` (20 ms apart, after ``NEUTRAL``) to the firmware in simavr, checks
    that the port gives the same replies and state, and returns each line's (parse,
    whole) cost in cycles: the most any of its bytes took (the module docstring says
    from where to where)."""
    times = [FIRST_COMMAND_S + NEUTRAL_LEAD_S + SPACING_S * k for k in range(len(lines))]
    # the last line's bytes all on the wire before the end (a byte reaches the USART one
    # byte time after it starts)
    tail = (len(lines[-1]) + 1) * UART_BYTE_CYCLES / F_CPU
    trace = Trace(duration=times[-1] + SPACING_S + tail,
                  serial=[(FIRST_COMMAND_S, NEUTRAL), *zip(times, lines, strict=True)])
    mega = VirtualMega(elf, hooks=(PASS_END, answer_symbol))
    try:
        for t, data in trace.serial:
            mega.send(data, at=round(t * F_CPU))
        recorder = Recorder(mega)
        recorder.run_until(round(trace.duration * F_CPU))
        recording = recorder.recording(trace)
        hits: list[Hit] = list(mega.hit_log)
    finally:
        mega.close()
    report = compare(recording)
    assert not report.mismatches, "\n".join(
        [str(m) for m in report.mismatches[:10]] + [trace.describe()])

    sent = [NEUTRAL, *lines]
    owner = [k for k, line in enumerate(sent) for _ in line]    # the line of each byte
    costs = [[0, 0] for _ in sent]
    byte = -1
    start: int | None = None
    parse_done = False
    for hit in hits:
        if start is not None and hit.function in ("processByte", "controlTick", "rxGap", answer_symbol,
                                                  PASS_END):
            cost = costs[owner[byte]]
            if not parse_done:
                cost[0] = max(cost[0], hit.cycle - start)
                parse_done = True
            if hit.function != answer_symbol:
                cost[1] = max(cost[1], hit.cycle - start)
                start = None
        if hit.function == "processByte":
            byte += 1
            start, parse_done = hit.cycle, False
    assert byte + 1 == len(owner), "not every byte reached processByte"
    for (parse, whole), line in zip(costs[1:], lines, strict=True):
        for kind, cycles in (("parse", parse), ("whole", whole)):
            if cycles > WORST[kind][0]:
                WORST[kind] = (cycles, line)
    return [(parse, whole) for parse, whole in costs[1:]]


def _assert_within_budget(lines: list[bytes], costs: list[tuple[int, int]]) -> None:
    for line, (parse, whole) in zip(lines, costs, strict=True):
        assert parse <= PARSE_BUDGET, f"{line!r} took {parse} cycles to parse"
        assert whole <= WHOLE_BUDGET, f"{line!r} took {whole} cycles, its answer included"
        assert whole < RX_RING_FILL


# ---- number strings that seek the worst case ------------------------------------
def _digit_run(max_size: int) -> st.SearchStrategy[str]:
    n = st.integers(0, max_size)
    return st.one_of(st.text("0123456789", max_size=max_size), n.map(lambda k: "9" * k),
                     n.map(lambda k: "1" * k), n.map(lambda k: "0" * k))


@st.composite
def _exponent(draw: st.DrawFn) -> str:
    value = draw(st.one_of(st.integers(0, 99), st.integers(100, 99_999),
                           st.sampled_from([31999, 3200, 3199, 32, 38, 39, 45, 64, 99, 100, 999])))
    pad = draw(st.integers(0, 3))
    return (draw(st.sampled_from("eE")) + draw(st.sampled_from(["", "+", "-"]))
            + str(value).rjust(len(str(value)) + pad, "0"))


@st.composite
def number_text(draw: st.DrawFn) -> bytes:
    """A number as a host, a fuzzer or line noise may write it: long digit runs, many
    leading zeros, long fractions, exponents of every size and sign, signs, points,
    junk."""
    kind = draw(st.sampled_from(["built", "built", "built", "special", "junk"]))
    if kind == "special":
        return draw(st.sampled_from([b"inf", b"-inf", b"+inf", b"infinity", b"nan", b"-nan",
                                     b".", b"-", b"+", b"e5", b".e-31999", b"-.e99", b"0e-31999",
                                     b"1e", b"1e-", b"1e+", b"1.2.3e-999", b"+-1", b"1e-31999x"]))
    if kind == "junk":
        return draw(st.text("0123456789.eE+-xn", min_size=1, max_size=40)).encode()
    text = draw(st.sampled_from(["", "", "+", "-"]))
    text += "0" * draw(st.integers(0, 30)) + draw(_digit_run(30))
    if draw(st.booleans()):
        text += "." + "0" * draw(st.integers(0, 30)) + draw(_digit_run(30))
    if draw(st.booleans()):
        text += draw(_exponent())
    if draw(st.integers(0, 9)) == 0:
        text += draw(st.sampled_from(["x", ".", "e", "-", "0.5", "e5"]))
    return (text or "0").encode()


@st.composite
def command_line(draw: st.DrawFn) -> bytes:
    """A number string (or two) in every place the protocol takes one, bare or framed."""
    a, b = draw(number_text()), draw(number_text())
    context = draw(st.sampled_from(["x", "t", "xt", "wheel", "set"]))
    if context == "x":
        command = b"x:" + a + b",t:0,"
    elif context == "t":
        command = b"x:0,t:" + a + b","
    elif context == "xt":
        command = b"x:" + a + b",t:" + b + b","
    elif context == "wheel":
        command = b"rp" + a + b",lp" + b + b","
    else:
        name = draw(st.sampled_from([p.name for p in PARAMS if p.name != "watchdog_ms"]))
        command = f"set:{name}=".encode() + a
    # The leading line end ends whatever an overlong line left behind.
    if draw(st.booleans()):
        return b"\n" + frame(command, draw(st.integers(0, 65535)))
    return b"\n" + command + (b"\n" if context == "set" else b"")


# ---- the tests -------------------------------------------------------------------
@pytest.mark.simavr
@settings(max_examples=EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(lines=st.lists(command_line(), min_size=1, max_size=4))
def test_no_line_takes_more_than_1ms_to_parse(elf: Path, answer_symbol: str,
                                             lines: list[bytes]) -> None:
    costs = line_costs(lines, elf, answer_symbol)
    target(float(max(parse for parse, _ in costs)), label="parse cycles")
    target(float(max(whole for _, whole in costs)), label="whole cycles")
    _assert_within_budget(lines, costs)


#: Lines that were slow before the rule, and the costliest valid ones after it:
#: (line, the reply; the firmware's is the port's, by the lock step).
KNOWN = [
    (b"x:1e-31999,t:0,", b"ERR:range"),
    (b"x:1e-31999,t:1e-31999,", b"ERR:range"),
    (b"set:kp_l=1e-31999\n", b"ERR:range"),
    (b"x:9.99999e-9999,t:0,", b"ERR:range"),
    (b"x:0e-31999,t:0,", b"ERR:range"),
    (b"x:0." + b"0" * 23 + b"1,t:0,", b"ERR:number"),          # 25 digits
    (b"x:0." + b"0" * 22 + b"1,t:0,", None),                   # 24: accepted
    (frame(b"x:1.000000000000e-99,t:1.00000000000e-99,", 65535), b"ACK:65535"),
    (frame(b"x:-0.000000000001e-99,t:-0.00000000001e-99,", 65535), b"ACK:65535"),
    (frame(b"rp0.0000000000001e-99,lp0.000000000001e-99,", 65535), b"ACK:65535"),
    (frame(b"set:kp_l=9.999999999999999999999e+00", 65535), b"PAR:kp_l,10.0000"),
    (frame(b"save", 65535), b"ACK:65535"),         # packs the block, writes its first byte
    (frame(b"defaults", 65535), b"ACK:65535"),
]


@pytest.mark.simavr
def test_known_lines_within_budget(elf: Path, answer_symbol: str) -> None:
    lines = [b"\n" + line for line, _ in KNOWN]
    costs = line_costs(lines, elf, answer_symbol)
    _assert_within_budget(lines, costs)


@pytest.mark.parametrize(("line", "reply"), KNOWN)
def test_known_lines_reply_on_the_port(line: bytes, reply: bytes | None) -> None:
    fw = setup(0)                       # booted, its neutral command stood two ticks
    fw.tick(50, 0, 0)
    fw.feed(NEUTRAL)
    fw.tick(100, 0, 0)
    fw.tick(150, 0, 0)
    out = fw.feed(line)
    if reply is None:
        assert out == b""
    else:
        assert out.splitlines()[0] == reply


# ---- the rule on the port: what it refuses, and that the hosts' numbers pass ---
@pytest.mark.parametrize(("text", "reason"), [
    (b"1" * C.NUMBER_MAX_DIGITS, None),
    (b"1" * (C.NUMBER_MAX_DIGITS + 1), "number"),
    (b"0." + b"0" * (C.NUMBER_MAX_DIGITS - 1), None),
    (b"0." + b"0" * C.NUMBER_MAX_DIGITS, "number"),       # leading zeros count
    (b"1e99", None), (b"1e-99", None), (b"1E+05", None), (b"1e-5", None),
    (b"1e100", "range"), (b"1e-005", "range"), (b"1e-31999", "range"), (b"0e-31999", "range"),
    (b"1." + b"0" * 30 + b"e-31999", "number"),           # the digits are counted first
    (b".e-31999", None), (b"e-31999", None),               # no digit: strtod refuses it
    (b"1.2.3e-31999", None), (b"-nan", None), (b"inf", None), (b"1e-31999x", "range"),
])
def test_number_in_reach(text: bytes, reason: str | None) -> None:
    if reason is None:
        number_in_reach(text, 0)
    else:
        with pytest.raises(ParseError) as err:
            number_in_reach(text, 0)
        assert err.value.reason == reason


def _in_reach(text: bytes) -> bool:
    try:
        number_in_reach(text, 0)
    except ParseError:
        return False
    return True


@given(v=st.floats(-MAX_LINEAR, MAX_LINEAR), w=st.floats(-MAX_ANGULAR, MAX_ANGULAR),
       r=st.floats(-MAX_WHEEL, MAX_WHEEL), left=st.floats(-MAX_WHEEL, MAX_WHEEL))
def test_the_codecs_motion_numbers_parse_unchanged(v: float, w: float, r: float,
                                                   left: float) -> None:
    cmdvel = encode_cmdvel(v, w)
    x_text, t_text = (part[2:] for part in cmdvel.split(b",")[:2])
    wheel = encode_wheel(r, left)
    r_text, l_text = (part[2:] for part in wheel.split(b",")[:2])
    for text in (x_text, t_text, r_text, l_text):
        assert parse_number(text, 0, True) == strtod(text)[0]


@given(data=st.data())
def test_the_codecs_parameter_numbers_parse_unchanged(data: st.DataObject) -> None:
    """``encode_set`` (6 significant digits), a binary64's shortest repr and the CAN
    gateway's ``board_text`` all stay within the rule, so the board reads them as
    before."""
    name = data.draw(st.sampled_from([n for n in PARAM_RANGES if n not in INTEGER_PARAMS]))
    low, high = PARAM_RANGES[name]
    value = data.draw(st.floats(low, high) | st.sampled_from(
        [0.0, 1e-5, 1e-99, 1e-100, 5e-324, low, high]).filter(lambda x: low <= x <= high))
    text = encode_set(name, value).partition(b"=")[2]
    assert _in_reach(text), text
    if value >= 1e-99:
        assert strtod(text)[0] == strtod(f"{value:.6g}".encode())[0]
    else:
        assert strtod(text)[0] == 0.0 == strtod(f"{value:.6g}".encode())[0]
    assert _in_reach(repr(value).encode()) or value < 1e-99
    assert _in_reach(board_text(strtod(text)[0]))
