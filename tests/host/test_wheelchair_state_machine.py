"""A hypothesis state machine driving the ``Wheelchair`` API against the in-process
simulated board (``wcsim://``: the bit-exact port of the firmware with the pymunk
plant), with the board watched from inside.

Rules, in any order: ``set_velocity`` / ``set_wheels`` / ``stop`` (in range, beyond
the board's ``max_wheel``, and out of range: ValueError, nothing sent), ``estop`` and
``reset_estop``, ``get_param`` / ``set_param`` over every parameter of the spec (in
range; out of range through the API: ValueError, nothing sent; out of range on the
wire: the board's ``NAK:<seq>,range`` as ``WcdriveCommandError``), silence past the
watchdog (measured on the board's clock, the TLM ``millis``), answers lost on the way
back (a corrupted byte: the line never parses) or left out by the board (its budget
of 3 answers a tick, which 4 quick requests or refused motion before a request use
up), request lines corrupted on the way out (sent again, once), the board's output
frozen while the port stays open (the host marks the link lost, refuses motion, and
recovers by itself when the lines flow again), and an unplug.

Every line the host writes is a protocol-v3 frame with its own sequence number, motion
included (fire and forget); motion frames share the counter and the send order with
the requests, so a TLM line that reports a later motion frame proves that a request
reached the board.

Reconnect: the link is *unplugged* (its reads raise, as pyserial's do when a USB
device goes away) and the session reopens it (``Wheelchair(..., reopen=...)``, the
device-path code path) onto a fresh board, which has reset: default parameters,
CMDVEL at rest, no e-stop latched. The host view (protocol version, firmware, status)
is rebuilt from the new board's handshake; a latched e-stop is the one thing the host
keeps, and it re-latches it on the new board, so an unplug never releases it.

The board side is observed, not modelled from the host's intent alone: ``BoardProbe``
wraps the firmware's ``feed``/``tick`` on the board's own thread and logs every line
the firmware finished (its sequence number, its command and whether the firmware
accepted it) and every watchdog stop, on the board's clock. The model applies that log
in order and checks, after every step:

- the host's ``estop_latched`` is the board's ``estopLatched``;
- every parameter is the binary32 value of the last accepted ``set:`` (and
  ``set_param``/``get_param`` returned it as the board printed it);
- mode and targets (pending ones during a pivot) are the last accepted motion
  command's, unless a watchdog stop or the e-stop came after it; a watchdog stop
  happens only when a motion command is in force and no earlier than ``watchdog_ms``
  (the value the host set) after it;
- no request is acted on twice: each sequence number is accepted at most once, and
  each ``set_param``/``estop``/``reset_estop`` call makes the board accept its command
  exactly once, whatever was lost on the way;
- the link is up (``link_ok``) between steps, and its events alternate, ``LinkLost``
  then ``LinkRestored``;
- neutral before motion (docs/safety.md): the board waits for a neutral command from
  its boot, a ``reset`` that released the e-stop and a watchdog stop of motion (not of
  a stop), until one has stood ``NEUTRAL_TICKS`` ticks with no motion after it; motion
  it refuses meanwhile starts the count over. The host refuses motion
  (``WcdriveNeutralError``, nothing sent) only while the board waits or its latest TLM
  line said so, and sends motion the board refuses only when the wait began after that
  line. The program sends its neutral as connect() does at the start, by ``stop`` or
  ``wait_for_neutral`` after a watchdog stop or a reconnect, and ``reset_estop``
  returns once the board has confirmed one.

Each step also checks its own call: a motion call sends one line, which the board takes
as the kinematics of the arguments (to the 3 decimals on the wire) and refuses only for
a wheel speed beyond its ``max_wheel``. Run time: the board runs 5 to 20 times faster
than the wall clock and every wait is on its clock; the fast depth (10 examples of 50
steps) takes 5 to 13 s, the thorough one (capped at 100 examples) 65 to 110 s on 2
cores (a freeze costs a link timeout of wall-clock time, so it runs once an example at
most).
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass

import pytest
import serial
from hypothesis import HealthCheck, event, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

import wcdrive
from tests.conftest import thorough
from tests.support.board_of import board_of
from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.f32 import f32
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.errors import WcdriveCommandError, WcdriveConnectionError, WcdriveEstopError, WcdriveNeutralError
from wcdrive.firmware import constants as C
from wcdrive.firmware.commands import parse
from wcdrive.firmware.state import FirmwareState
from wcdrive.host.requests import Request
from wcdrive.host.telemetry import LinkLost, LinkRestored
from wcdrive.protocol.codec import MAX_ANGULAR, MAX_LINEAR, MAX_WHEEL, encode_cmdvel, encode_wheel
from wcdrive.protocol.spec import PARAMETERS, PROFILE_PARAMETERS, PROFILES
from wcdrive.transports.faulty import FaultyPort

BY_NAME = {p.name: p for p in PARAMETERS}
DEFAULTS = {p.name: getattr(FirmwareState(), p.field) for p in PARAMETERS}
#: Wall-clock guards only: every wait below is on the board's own clock.
WALL_TIMEOUT = 30.0
#: The link timeout while the board's output is frozen (5 to 40 feedback periods of
#: these boards): short, since the freeze waits for it.
FREEZE_LINK_TIMEOUT = 0.1


# ---- the board, watched from inside ----------------------------------------------------
@dataclass(frozen=True)
class Line:
    """A line the firmware finished: its sequence number (None: not sequenced), its
    command and whether the firmware accepted it (``rejectedCount`` unchanged)."""

    millis: int
    seq: int | None
    body: bytes
    accepted: bool


@dataclass(frozen=True)
class WatchdogStop:
    """A tick that sent ``EVT:WATCHDOG``: its ``millis``, the firmware's ``lastCmdTime``
    and whether the firmware waits for a neutral command after it (``needNeutral``)."""

    millis: int
    last_command: int
    waits: bool


@dataclass(frozen=True)
class NeutralWait:
    """The firmware began (``waits``) or ended its wait for a neutral command
    (``needNeutral``): on a line it finished or on a tick, at ``millis``."""

    millis: int
    waits: bool


class BoardProbe:
    """Logs, on the board's thread, every line the firmware of ``board`` finishes, every
    watchdog stop and every change of its wait for a neutral command (by wrapping
    ``Firmware.feed``/``tick`` of that one board)."""

    FRAMED = re.compile(rb"\$(\d{1,5}):(.*)\*[0-9A-F]{4}", re.S)

    def __init__(self, board: SimulatedBoard) -> None:
        self.board = board
        self.log: list[Line | WatchdogStop | NeutralWait] = []
        self._line = bytearray()
        fw, timer = board.loop.fw, board.loop.timer
        feed, tick = fw.feed, fw.tick

        def probed_feed(data: bytes) -> bytes:
            out = bytearray()
            for chunk in re.split(rb"(?<=\n)", data):
                if not chunk:
                    continue
                rejected, waits = fw.state.rejectedCount, fw.state.needNeutral
                out += feed(chunk)
                self._line += chunk
                if chunk.endswith(b"\n"):
                    self._finish(timer.millis, fw.state.rejectedCount == rejected)
                if fw.state.needNeutral != waits:
                    self.log.append(NeutralWait(timer.millis, bool(fw.state.needNeutral)))
            return bytes(out)

        def probed_tick(now: int, *args: int, **kwargs: int) -> bytes:
            waits = fw.state.needNeutral
            out = tick(now, *args, **kwargs)
            if b"EVT:WATCHDOG" in out:
                self.log.append(WatchdogStop(now, fw.state.lastCmdTime, bool(fw.state.needNeutral)))
            elif fw.state.needNeutral != waits:
                self.log.append(NeutralWait(now, bool(fw.state.needNeutral)))
            return out

        with board._lock:
            fw.feed = probed_feed      # type: ignore[method-assign]
            fw.tick = probed_tick      # type: ignore[method-assign,assignment]

    def _finish(self, millis: int, accepted: bool) -> None:
        line = bytes(self._line).rstrip(b"\r\n")
        self._line.clear()
        m = self.FRAMED.fullmatch(line)
        if m is None:
            self.log.append(Line(millis, None, line, accepted))
        else:
            self.log.append(Line(millis, int(m[1]), m[2], accepted))


class Link(FaultyPort):
    """The host's end of one ``wcsim://`` port behind a ``FaultyPort``, the session's
    ``Port``: ``written`` counts the bytes that reached the board, ``lose`` loses the
    board's next answers and PAR lines (as a corrupted byte would: the line never
    parses), ``corrupt_next_request`` flips a bit of the next request line's command
    (the board answers ``ERR:checksum``), ``cut(tx=False)`` drops every line of the
    board while the port stays open (``restore``), and ``unplug`` makes its calls raise,
    as pyserial's do when a USB device goes away. The random choices come from
    ``seed``, the board's seed."""

    ANSWER = re.compile(rb"^(?:ACK|NAK):\d+")
    #: Group 1, where the flip goes: the first byte of a request's command.
    REQUEST = re.compile(rb"^\$\d+:(?=estop|reset|get:|set:)(.)")
    BODY = re.compile(rb"\$\d+:(.*)\*", re.S)

    def __init__(self, speed: float, seed: int) -> None:
        super().__init__(serial.serial_for_url(f"wcsim://?speed={speed}&seed={seed}", timeout=0.1), seed=seed)
        self.probe = BoardProbe(board_of(self))
        self._answers = self.rx.drop(match=self.ANSWER, count=0)
        self._data = self.rx.drop(match=rb"^PAR:", count=0)
        self._requests = self.tx.flip(match=self.REQUEST, count=0)

    @property
    def written(self) -> int:
        """Bytes that reached the board."""
        return self.tx.passed

    @property
    def lost(self) -> list[bytes]:
        """The board's lines lost so far."""
        return [line for rule in (self._answers, self._data) for line, _ in rule.hits]

    @property
    def corrupted(self) -> set[bytes]:
        """The commands the board got instead of the corrupted ones."""
        return {m[1] for _, line in self._requests.hits if line and (m := self.BODY.match(line))}

    def lose(self, answers: int, data: int) -> None:
        """The next ``answers`` ACK/NAK lines and the next ``data`` PAR lines are lost."""
        with self._lock:
            self._answers.count, self._data.count = answers, data

    def corrupt_next_request(self) -> None:
        """The next request line reaches the board with a flipped bit."""
        with self._lock:
            self._requests.count = 1


# ---- strategies ------------------------------------------------------------------------
def _outside(limit: float) -> st.SearchStrategy[float]:
    beyond = st.floats(min_value=limit, exclude_min=True)
    return st.one_of(beyond, beyond.map(lambda v: -v), st.sampled_from([math.nan, math.inf, -math.inf]))


def _in_range(name: str) -> st.SearchStrategy[float]:
    p = BY_NAME[name]
    if p.integer:
        return st.integers(int(p.low), int(p.high)).map(float)
    return st.floats(min_value=p.low, max_value=p.high)


def _api_out_of_range(name: str) -> st.SearchStrategy[float]:
    """What the codec refuses: outside the range, NaN, or a fraction of a millisecond."""
    p = BY_NAME[name]
    bad = st.one_of(st.floats(max_value=p.low, exclude_max=True),
                    st.floats(min_value=p.high, exclude_min=True), st.just(math.nan))
    if p.integer:
        bad = bad | st.floats(p.low + 0.01, p.high - 0.01).filter(lambda v: v != int(v))
    return bad


def _wire_out_of_range(name: str) -> st.SearchStrategy[bytes]:
    """Text the codec would refuse but the board parses and finds out of range."""
    p = BY_NAME[name]
    if p.integer:
        below = [st.integers(0, int(p.low) - 1)] if p.low > 0 else []
        return st.one_of(st.integers(int(p.high) + 1, 9999), *below).map(lambda v: b"%d" % v)
    above = st.floats(1.01, 1000.0).map(lambda k: p.high * k + 0.01)
    if p.low > 0:
        above = above | st.floats(0.0, 0.99).map(lambda k: p.low * k)
    return above.map(lambda v: f"{v:.6g}".encode())


param_names = st.sampled_from(sorted(BY_NAME))
#: In range, every parameter but brake_fitted 1: this simulated chair has no brake, whose
#: driver would see an open coil and latch BRAKE_OPEN for good (tests/host/test_brake_host.py
#: drives a chair with one).
in_range_settings = st.sampled_from(sorted(set(BY_NAME) - {"brake_fitted"})).flatmap(
    lambda n: st.tuples(st.just(n), _in_range(n)))
api_bad_settings = param_names.flatmap(lambda n: st.tuples(st.just(n), _api_out_of_range(n)))
wire_bad_settings = param_names.flatmap(lambda n: st.tuples(st.just(n), _wire_out_of_range(n)))


def _up_to(limit: float) -> st.SearchStrategy[float]:
    """Anything in ±``limit``, and often the last thousandth of the range (where the
    3 decimals on the wire and the board's ``strtod`` meet its binary32 limit)."""
    edge = st.floats(limit - 0.001, limit) | st.just(limit)
    return st.one_of(st.floats(-limit, limit), edge, edge.map(lambda v: -v))


linear = _up_to(MAX_LINEAR)
angular = _up_to(MAX_ANGULAR)
wheel = _up_to(MAX_WHEEL)


def _note(what: str) -> None:
    """``hypothesis.event`` (shown by --hypothesis-show-statistics), also outside a test."""
    try:
        event(what)
    except InvalidArgument:
        pass


def _wait(condition: Callable[[], bool], what: str, timeout: float = WALL_TIMEOUT) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.002)


# ---- the machine -------------------------------------------------------------------------
class WheelchairMachine(RuleBasedStateMachine):
    """The ``Wheelchair`` API against a simulated board, the board watched from inside."""

    def __init__(self) -> None:
        super().__init__()
        self.links: list[Link] = []
        self.chair: wcdrive.Wheelchair | None = None
        self.link_events: list[LinkLost | LinkRestored] = []

    # ---- opening, reopening ----------------------------------------------------------
    @initialize(speed=st.sampled_from([5.0, 10.0, 20.0]), seed=st.integers(0, 3))
    def connect(self, speed: float, seed: int) -> None:
        self.speed, self.seed = speed, seed
        self._new_board_model()
        self.latched = False
        self.freezes = 0
        # 1 s: a board thread that falls behind on a loaded machine sends nothing until it
        # has caught up; a freeze lowers it (FREEZE_LINK_TIMEOUT) while it lasts
        self.chair = wcdrive.Wheelchair(self._open(), reopen=self._open, reconnect_timeout=10.0,
                                        link_timeout=1.0, stop_on_signals=False)
        self.chair.on_link(self.link_events.append)
        # as wcdrive.connect does: the board boots, then the handshake and a neutral
        # command the board confirms (it drives only after one)
        self.chair.wait_for_telemetry(WALL_TIMEOUT)
        assert self.chair.wait_for_handshake(WALL_TIMEOUT) == 4
        self.chair.wait_for_neutral(WALL_TIMEOUT)
        self._settle()
        assert not self.waits

    def _open(self) -> Link:
        link = Link(self.speed, self.seed)
        self.links.append(link)
        return link

    def _new_board_model(self) -> None:
        """What a board holds just after reset."""
        self.params = dict(DEFAULTS)
        # the drive profiles' table: set:profile puts a row's drive limits in force, set:
        # of a drive limit changes the row in force (docs/safety.md, "Drive profiles")
        self.profiles = [{name: float(f32(v)) for name, v in zip(PROFILE_PARAMETERS, p.values, strict=True)}
                         for p in PROFILES]
        self.mode = C.MODE_CMDVEL
        self.target = (0.0, 0.0)            # (right, left): the board's, or pending in a pivot
        self.armed = False                  # a motion command is in force: the watchdog may stop it
        self.command_millis = 0
        self.board_estop = False
        # neutral before motion: the board waits for a neutral command from its boot on
        self.waits = True
        self.neutral_since: int | None = None   # the neutral command the wait counts from
        self.waits_began: int | None = 0        # the board's millis: the wait began
        self.waits_ended: int | None = None     # ... and ended, the last time
        self.last_watchdog: int | None = None
        self.seqs_done: set[int] = set()
        self.consumed = 0
        self.lost_seen = 0
        self.suppressed_seen = 0

    @property
    def link(self) -> Link:
        return self.links[-1]

    def teardown(self) -> None:
        if self.chair is not None:
            self.chair.close()
        for link in self.links:
            link.close()

    # ---- the board's side ----------------------------------------------------------------
    def _settle(self) -> tuple[FirmwareState, list[Line]]:
        """Waits until the board has read every byte the host wrote, applies what the
        board did meanwhile to the model, and returns the board's state then and the
        lines it finished."""
        link = self.link
        board = board_of(link)
        state = board.loop.fw.state
        deadline = time.monotonic() + WALL_TIMEOUT
        while True:
            with board._lock:
                if state.rxCount == link.written:
                    snapshot = state.copy()
                    new = link.probe.log[self.consumed:]
                    self.consumed = len(link.probe.log)
                    break
            assert time.monotonic() < deadline, "the board never read what the host wrote"
            time.sleep(0.001)
        self._apply(new)
        lines = [e for e in new if isinstance(e, Line)]
        # what the run went through (--hypothesis-show-statistics)
        if any(isinstance(e, WatchdogStop) for e in new):
            _note("the watchdog stopped the chair")
        if any(e.body in link.corrupted for e in lines):
            _note("a request line was corrupted on the way out")
        if len(link.lost) > self.lost_seen:
            self.lost_seen = len(link.lost)
            _note("an answer was lost on the way back")
        if snapshot.errSuppressed > self.suppressed_seen:
            self.suppressed_seen = snapshot.errSuppressed
            _note("the board left an answer out (3 a tick)")
        if any(e.body == b"reset" and not e.accepted for e in lines):
            _note("reset refused until parked")
        if snapshot.pivotPhase:
            _note("a pivot in progress")
        return snapshot, lines

    def _begin_wait(self, millis: int) -> None:
        self.waits, self.neutral_since, self.waits_began = True, None, millis

    def _apply(self, entries: list[Line | WatchdogStop | NeutralWait]) -> None:
        for e in entries:
            if isinstance(e, WatchdogStop):
                assert self.armed, f"watchdog stop at {e.millis} ms with no motion command in force"
                assert e.millis - e.last_command >= self.params["watchdog_ms"], (
                    f"watchdog stop {e.millis - e.last_command} ms after the last command, "
                    f"watchdog_ms is {self.params['watchdog_ms']}")
                # a stop of motion: the board waits for a neutral command; after a stop
                # command it asks for nothing
                if self.target != (0.0, 0.0):
                    self._begin_wait(e.millis)
                assert e.waits == self.waits, (e, self.target)
                self.target, self.armed, self.last_watchdog = (0.0, 0.0), False, e.millis
                continue
            if isinstance(e, NeutralWait):
                if e.waits:
                    assert self.waits, f"the board began to wait for neutral at {e.millis} ms unasked"
                else:
                    # confirmed: a neutral command stood NEUTRAL_TICKS ticks, no motion after it
                    assert self.waits and self.neutral_since is not None, e
                    assert e.millis - self.neutral_since >= (C.NEUTRAL_TICKS - 1) * C.CONTROL_PERIOD_MS, (
                        e, self.neutral_since)
                    self.waits, self.neutral_since, self.waits_ended = False, None, e.millis
                continue
            if not e.accepted:
                motion = (e.body not in self.link.corrupted and e.body not in (b"estop", b"reset")
                          and not e.body.startswith((b"set:", b"get:", b"hello")))
                result = parse(e.body, self.params["max_wheel"]) if motion else "not motion"
                if not isinstance(result, str) and result is not None and result[1:] != (0.0, 0.0):
                    # motion refused: the e-stop, or the wait for neutral (which starts over)
                    assert self.board_estop or self.waits, f"the board refused {e.body!r}"
                    if not self.board_estop:
                        self.neutral_since = None
                continue
            if e.seq is not None:
                assert e.seq not in self.seqs_done, (
                    f"the board acted twice on sequence number {e.seq} ({e.body!r})")
                self.seqs_done.add(e.seq)
            body = e.body
            if body == b"estop":
                self.board_estop, self.target, self.armed = True, (0.0, 0.0), False
            elif body == b"reset":
                if self.board_estop:            # released: motion after a neutral command
                    self._begin_wait(e.millis)
                self.board_estop = False
            elif body.startswith(b"set:"):
                name, text = body[4:].decode().split("=")
                self.params[name] = int(text) if BY_NAME[name].integer else strtod(text.encode())[0]
                if name == "profile":
                    self.params.update(self.profiles[self.params[name]])
                elif name in PROFILE_PARAMETERS:
                    self.profiles[self.params["profile"]][name] = self.params[name]
            elif body.startswith(b"get:") or body in (b"hello", b"hello:4"):
                pass
            else:
                result = parse(body, self.params["max_wheel"])
                assert not isinstance(result, str), f"accepted {body!r}, which is {result}"
                assert result is not None, f"a PPM loss frame {body!r}"
                mode, right, left = result
                if self.board_estop:
                    assert right == 0.0 and left == 0.0, f"moved while latched: {body!r}"
                    continue
                if self.waits:
                    assert right == 0.0 and left == 0.0, f"moved while waiting for neutral: {body!r}"
                    if self.neutral_since is None:
                        self.neutral_since = e.millis
                self.mode, self.target, self.armed = mode, (right, left), True
                self.command_millis = e.millis

    def _expect_lines(self, lines: list[Line], *once: bytes, also: bytes | None = None) -> None:
        """The board accepted each command of ``once`` exactly once; every other line it
        finished is a refused copy of one of them, the command ``also`` (any number of
        times: a read), or a line the link corrupted (refused)."""
        for body in once:
            n = sum(1 for e in lines if e.accepted and e.body == body)
            assert n == 1, f"the board acted {n} times on {body!r}: {lines}"
        stray = [e for e in lines if e.body not in once and e.body != also
                 and not (e.body in self.link.corrupted and not e.accepted)]
        assert not stray, f"unexpected lines: {stray}"

    def _chair(self) -> wcdrive.Wheelchair:
        assert self.chair is not None
        return self.chair

    def _host_telemetry(self) -> int | None:
        """The board's millis in the host's latest TLM line (None: none since the board
        reset or released its e-stop)."""
        status = self._chair().status
        return None if status is None else status.millis

    def _host_may_wait(self, seen: int | None) -> bool:
        """Whether the host may refuse motion for a neutral command (``WcdriveNeutralError``)
        when its latest TLM line, before the call, was the board's at ``seen`` ms: the
        board waits for one, or did at that line (the host learns of the end from the
        next), or the host has read no TLM line since a reset (it assumes the wait until
        one says), or an ``EVT:WATCHDOG`` came after that line (the TLM line of its tick
        follows at once and says whether the stop asks for a neutral command)."""
        if self.waits or seen is None:
            return True
        return any(t is not None and t > seen for t in (self.waits_ended, self.last_watchdog))

    # ---- motion ----------------------------------------------------------------------
    def _motion(self, call: Callable[[], None], mode: int, right: float, left: float, tol: float) -> None:
        """``call`` sends one motion line, unless the e-stop is latched (then it raises,
        sending nothing); the board takes it as (``mode``, ``right``, ``left``) to
        ``tol``, and refuses it only for a wheel speed beyond its ``max_wheel`` (a
        parameter the host does not check)."""
        written = self.link.written
        if self.latched:
            with pytest.raises(WcdriveEstopError):
                call()
            assert self.link.written == written, "a refused motion was sent"
            self._settle()
            return
        max_wheel = self.params["max_wheel"]
        seen = self._host_telemetry()
        try:
            call()
        except WcdriveNeutralError:
            # the board waits for a neutral command (a watchdog stop of motion, a reset,
            # the e-stop released) and the host knows: nothing sent
            assert self.link.written == written, "a refused motion was sent"
            _, lines = self._settle()
            assert lines == [], lines
            assert self._host_may_wait(seen), f"refused for neutral, the board waits for none (TLM at {seen})"
            _note("the host refused motion: the board waits for a neutral command")
            return
        _, lines = self._settle()
        assert len(lines) == 1 and lines[0].seq is not None, lines     # framed, not awaited
        line = lines[0]
        result = parse(line.body, max_wheel)            # what the board made of it
        if isinstance(result, str):
            beyond = mode == C.MODE_WHEEL and max(abs(right), abs(left)) > max_wheel - tol
            assert result == "range" and beyond, (
                f"the board refused {line.body!r} ({result}) for ({right}, {left}) rad/s")
            assert not line.accepted
            return
        if not line.accepted:
            # refused for neutral (``_apply`` checked that the board waited): the wait
            # began after the host's latest TLM line, which it could not know of yet
            assert seen is not None and self.waits_began is not None and self.waits_began > seen, (
                f"the host sent {line.body!r} while the board waited for neutral since "
                f"{self.waits_began} ms, its TLM at {seen} ms said so")
            _note("the board refused motion the host sent before it read of the wait for neutral")
            return
        assert line.accepted, line
        assert result is not None
        assert result[0] == mode
        assert result[1:] == pytest.approx((right, left), abs=tol), (line.body, right, left)

    @rule(v=linear, w=angular)
    def set_velocity(self, v: float, w: float) -> None:
        # the kinematics, independently of the port's parser; the wire has 3 decimals
        right = (v + w * C.WHEELBASE / 2) / C.WHEEL_RADIUS
        left = (v - w * C.WHEELBASE / 2) / C.WHEEL_RADIUS
        peak = max(abs(right), abs(left))
        k = min(1.0, self.params["max_wheel"] / peak) if peak else 1.0
        self._motion(lambda: self._chair().set_velocity(v, w), C.MODE_CMDVEL, right * k, left * k,
                     tol=(0.0015 + 0.0015 * C.WHEELBASE / 2) / C.WHEEL_RADIUS)

    @rule(left=wheel, right=wheel)
    def set_wheels(self, left: float, right: float) -> None:
        self._motion(lambda: self._chair().set_wheels(left, right), C.MODE_WHEEL, right, left, tol=0.0015)

    @rule()
    def stop(self) -> None:
        """A stop goes out even while the e-stop is latched, and the board takes it."""
        self._chair().stop()
        _, lines = self._settle()
        assert [(e.body, e.accepted) for e in lines] == [(encode_cmdvel(0.0, 0.0), True)]

    @rule(vw=st.one_of(st.tuples(_outside(MAX_LINEAR), angular), st.tuples(linear, _outside(MAX_ANGULAR))))
    def set_velocity_out_of_range(self, vw: tuple[float, float]) -> None:
        self._refused_locally(lambda: self._chair().set_velocity(*vw))

    @rule(left=_outside(MAX_WHEEL), right=wheel, swap=st.booleans())
    def set_wheels_out_of_range(self, left: float, right: float, swap: bool) -> None:
        if swap:
            left, right = right, left
        self._refused_locally(lambda: self._chair().set_wheels(left, right))

    def _refused_locally(self, call: Callable[[], object]) -> None:
        written = self.link.written
        with pytest.raises(ValueError):
            call()
        assert self.link.written == written, "an out-of-range command went out"
        _, lines = self._settle()
        assert lines == []

    @precondition(lambda self: not self.latched and self.params["max_wheel"] < C.MAX_WHEEL_SPEED - 1.0)
    @rule(n=st.integers(1, 4), name=param_names)
    def refused_burst_then_request(self, n: int, name: str) -> None:
        """Motion the board refuses (beyond its max_wheel: ``ERR:range``) right before a
        request: with the board's budget of 3 answers a tick, the request's answer may
        never be sent."""
        chair = self._chair()
        too_fast = min(MAX_WHEEL, self.params["max_wheel"] + 0.5)
        sent = 0
        for _ in range(n):
            seen, written = self._host_telemetry(), self.link.written
            try:
                chair.set_wheels(too_fast, too_fast)
                sent += 1
            except WcdriveNeutralError:             # refused at the host: nothing sent
                assert self.link.written == written and self._host_may_wait(seen)
        value = chair.get_param(name)
        snapshot, lines = self._settle()
        refused = encode_wheel(too_fast, too_fast)
        assert [(e.body, e.accepted) for e in lines if e.body == refused] == [(refused, False)] * sent
        self._expect_lines([e for e in lines if e.body != refused], also=f"get:{name}".encode())
        self._check_printed(name, value, snapshot)

    # ---- e-stop ----------------------------------------------------------------------
    @rule()
    def estop(self) -> None:
        chair = self._chair()
        chair.estop()
        assert chair.estop_latched
        self.latched = True
        _, lines = self._settle()
        self._expect_lines(lines, b"estop")

    @rule()
    def reset_estop(self) -> None:
        """Releasing a latched e-stop, the host also sends the neutral command the board
        then waits for, and returns once the board has confirmed it."""
        chair = self._chair()
        released = self.latched
        chair.reset_estop(timeout=WALL_TIMEOUT)
        assert not chair.estop_latched
        self.latched = False
        _, lines = self._settle()
        stop = encode_cmdvel(0.0, 0.0)
        self._expect_lines([e for e in lines if e.body != stop], b"reset")
        if released:
            assert [e.accepted for e in lines if e.body == stop][:1] == [True], lines
            assert not self.waits, "reset_estop() returned before the board took a neutral command"
        else:
            assert not any(e.body == stop for e in lines), lines

    @precondition(lambda self: not self.latched)
    @rule()
    def wait_for_neutral(self) -> None:
        """The program drives on after a watchdog stop or a reset: it sends stops until
        the board has confirmed one (at once when the board waits for none)."""
        chair = self._chair()
        chair.wait_for_neutral(WALL_TIMEOUT)
        _, lines = self._settle()
        stop = encode_cmdvel(0.0, 0.0)
        assert lines and all(e.body == stop and e.accepted for e in lines), lines
        assert not self.waits, "wait_for_neutral() returned before the board took a neutral command"

    @precondition(lambda self: self.latched)
    @rule(v=st.floats(0.0005, MAX_LINEAR), backwards=st.booleans())
    def motion_while_latched(self, v: float, backwards: bool) -> None:
        v = -v if backwards else v
        written = self.link.written
        with pytest.raises(WcdriveEstopError):
            self._chair().set_velocity(v, 0.0)
        assert self.link.written == written, "a refused motion was sent"

    # ---- parameters ------------------------------------------------------------------
    def _check_printed(self, name: str, value: float, snapshot: FirmwareState) -> None:
        """``value`` is the board's, as it prints it (4 decimals)."""
        held = getattr(snapshot, BY_NAME[name].field)
        assert held == self.params[name]
        assert abs(value - held) <= 0.5e-4 + 1e-6 * abs(held), (name, value, held)

    @rule(name=param_names)
    def get_param(self, name: str) -> None:
        value = self._chair().get_param(name)
        snapshot, lines = self._settle()
        self._expect_lines(lines, also=f"get:{name}".encode())
        assert any(e.accepted for e in lines)
        self._check_printed(name, value, snapshot)

    @rule(setting=in_range_settings)
    def set_param(self, setting: tuple[str, float]) -> None:
        name, requested = setting
        value = self._chair().set_param(name, requested)
        snapshot, lines = self._settle()
        sets = [e.body for e in lines if e.body.startswith(b"set:") and e.body not in self.link.corrupted]
        assert len(sets) >= 1 and len(set(sets)) == 1, lines
        self._expect_lines(lines, sets[0], also=f"get:{name}".encode())
        self._check_printed(name, value, snapshot)
        # the codec writes 6 significant digits: the board holds that, as binary32
        assert self.params[name] == pytest.approx(requested, rel=5e-6, abs=1e-30)

    @rule(setting=api_bad_settings)
    def set_param_out_of_range(self, setting: tuple[str, float]) -> None:
        name, value = setting
        self._refused_locally(lambda: self._chair().set_param(name, value))

    @rule(setting=wire_bad_settings)
    def set_param_refused_by_the_board(self, setting: tuple[str, bytes]) -> None:
        """What the codec refuses, sent anyway: the board's NAK reaches the caller."""
        name, text = setting
        request = Request.set_text(name, text)
        command = request.command
        with pytest.raises(WcdriveCommandError) as refused:
            self._chair()._session.request(request)
        assert refused.value.reason == "range"
        _, lines = self._settle()
        assert not any(e.accepted for e in lines if e.body == command), lines
        self._expect_lines([e for e in lines if e.body != command], also=f"get:{name}".encode())

    # ---- time, losses, the link ------------------------------------------------------
    @rule()
    def silence_past_the_watchdog(self) -> None:
        """No command for longer than watchdog_ms on the board's clock: a motion
        command in force is stopped, and the host hears of it."""
        chair = self._chair()
        self._settle()
        _wait(lambda: chair.status is not None, "a TLM line")
        status = chair.status
        assert status is not None
        start = self.command_millis if self.armed else status.millis
        until = start + self.params["watchdog_ms"] + 2 * C.CONTROL_PERIOD_MS + 5
        was_armed = self.armed
        heard = chair.events.count("WATCHDOG")
        _wait(lambda: (s := chair.status) is not None and s.millis >= until,
              f"the board's clock to reach {until} ms")
        self._settle()
        assert not self.armed, "the watchdog did not stop the chair"
        if was_armed:
            _wait(lambda: chair.events.count("WATCHDOG") > heard, "EVT:WATCHDOG at the host")

    @rule(answers=st.integers(0, 2), data=st.integers(0, 2))
    def lose_answers(self, answers: int, data: int) -> None:
        """The next ``answers`` ACK/NAK lines and the next ``data`` PAR lines are lost
        on the way to the host."""
        self.link.lose(answers, data)

    @rule()
    def corrupt_next_request(self) -> None:
        """The next request line reaches the board with a flipped bit: the board refuses
        it (``ERR:checksum``) and the session must send it again, once."""
        self.link.corrupt_next_request()

    @precondition(lambda self: self.freezes == 0)
    @rule(call=st.sampled_from(["set_velocity", "set_wheels", "get_param"]))
    def freeze_the_board_output(self, call: str) -> None:
        """The board's lines stop reaching the host while the port stays open: the
        host marks the link lost (``link_ok`` False, a ``LinkLost``), refuses motion
        and requests (``WcdriveConnectionError``, nothing sent), and recovers by itself
        once the lines flow again (a ``LinkRestored``). Once an example: each costs
        the link timeout in wall-clock time."""
        self.freezes += 1
        chair = self._chair()
        self._settle()
        events = len(self.link_events)
        chair.link_timeout = FREEZE_LINK_TIMEOUT
        self.link.cut(tx=False)
        try:
            # the flag flips first, then the LinkLost callback runs (another thread)
            _wait(lambda: not chair.link_ok and len(self.link_events) > events,
                  "the link to be marked lost and the LinkLost delivered")
            assert [type(e) for e in self.link_events[events:]] == [LinkLost]
            lost = self.link_events[events]
            assert isinstance(lost, LinkLost) and lost.silent_for >= chair.link_timeout
            written = self.link.written
            with pytest.raises(WcdriveConnectionError, match="lost"):
                if call == "set_velocity":
                    chair.set_velocity(0.2, 0.0)
                elif call == "set_wheels":
                    chair.set_wheels(1.0, 1.0)
                else:
                    chair.get_param("kp_l")
            assert self.link.written == written, "a command went out on a dead link"
        finally:
            self.link.restore()
        _wait(lambda: chair.link_ok and len(self.link_events) > events + 1,
              "the link to recover and the LinkRestored delivered")
        chair.link_timeout = 1.0
        assert [type(e) for e in self.link_events[events:]] == [LinkLost, LinkRestored]
        _note(f"the board's output froze (the link was lost and restored; {call} refused)")
        self._settle()

    @rule()
    def unplug_and_reconnect(self) -> None:
        chair = self._chair()
        self._settle()
        reconnects = chair.events.count("RECONNECTED")
        if self.latched:
            _note("unplugged with the e-stop latched")
        self.link.unplug()
        _wait(lambda: chair.events.count("RECONNECTED") > reconnects, "the session to reopen the port")
        self._new_board_model()
        chair.wait_for_telemetry(WALL_TIMEOUT)
        assert chair.wait_for_handshake(WALL_TIMEOUT) == 4
        assert chair.firmware == "final_control"
        _, lines = self._settle()
        # the new board hears hello first and, when the e-stop was latched, the e-stop
        # again; nothing else but a hello said again (one whose answer took longer than
        # the session's wait, as on a loaded machine: seen once in CI)
        bodies = [e.body for e in lines if e.accepted]
        assert bodies[:1] == [b"hello:4"], lines
        assert [b for b in bodies if b != b"hello:4"] == ([b"estop"] if self.latched else []), lines
        # a reset the program did not ask for: it drives on after a neutral command of
        # its own (stop() or wait_for_neutral()), not the host's
        assert self.waits and chair.needs_neutral

    # ---- invariants --------------------------------------------------------------------
    @invariant()
    def host_and_board_agree(self) -> None:
        if self.chair is None:
            return
        chair = self.chair
        s, _ = self._settle()
        assert chair.protocol_version == 4
        assert chair.link_ok, f"the link is down: {chair.since_last_line:.3f} s without a line"
        kinds = [type(e) for e in self.link_events]
        assert kinds == [LinkLost, LinkRestored] * (len(kinds) // 2), kinds
        assert bool(s.estopLatched) == self.board_estop == self.latched, (s.estopLatched, self.latched)
        assert bool(s.needNeutral) == self.waits, (s.needNeutral, self.waits)
        assert chair.estop_latched == self.latched
        for p in PARAMETERS:
            assert getattr(s, p.field) == self.params[p.name], (p.name, getattr(s, p.field))
        assert s.mode == self.mode
        held = (s.pendingR, s.pendingL) if s.pivotPhase else (s.targetR, s.targetL)
        assert held == self.target, (held, self.target, s.pivotPhase)
        assert "link lost" not in chair.errors


WheelchairMachine.TestCase.settings = settings(
    max_examples=min(settings().max_examples, 100 if thorough() else 10),    # ci: 65 to 110 s on 2 cores
    stateful_step_count=50,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
TestWheelchairStateMachine = WheelchairMachine.TestCase
