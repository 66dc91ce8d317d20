"""The host's request/answer core (``wcdrive.protocol.exchange.Exchange``), stepped with
no clock: frames sent, answers in any order, lost, repeated and stale, ``TLM:`` lines
reporting any number, the numbers wrapping at ``SEQ_MAX``.

``ExchangeMachine`` holds a model of the link beside the exchange (what was sent in
which order, what is in flight, what was answered) and checks, at every step:

- the numbering: each frame takes the next number after the last one, 1 to
  ``SEQ_MAX`` and round again, skipping the requests in flight; its bytes are
  ``codec.frame``'s and the firmware's ``unframe`` reads back the same number and
  command;
- each sending of a request settles at most once, and only while it is in flight;
  each motion frame is applied or refused at most once, never both (a ``NAK``'d motion
  is never reported as applied);
- a request is seen only by a ``TLM:`` line that reports it or a frame sent after it,
  and is lost only after its patience and two ``TLM:`` lines that do not (any time on
  a board that sends none);
- the requests in flight never exceed their bound.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from wcdrive.firmware.commands import unframe
from wcdrive.protocol.codec import SEQ_MAX, Ack, ExtendedTelemetry, Nak, Param, frame
from wcdrive.protocol.exchange import (
    Answered,
    Exchange,
    ExchangeEvent,
    InFlight,
    InFlightFull,
    MotionApplied,
    MotionRefused,
    Next,
    Outcome,
    Seen,
    answer_verdict,
    lost_answer_verdict,
    read_back_verdict,
)
from wcdrive.protocol.motion import velocity_command, wheel_command

PATIENCE = 0.3
BOUND = 3                       # requests in flight at once
MOTION = [velocity_command(0.3, 0.0), wheel_command(-1.0, 2.5), velocity_command(0.0, 0.0)]
REQUESTS = [b"get:kp_l", b"set:kp_l=7.5", b"estop", b"reset", b"save"]
REASONS = ["range", "estop", "fault", "busy"]


def _telemetry(seq: int, flags: int = 0) -> ExtendedTelemetry:
    return ExtendedTelemetry(0, 0, seq, 0, 0, 1, 1, 0, 0, flags, 0, 0, 1000)


@dataclass
class _Request:
    """The model of a request in flight."""

    entry: InFlight
    body: bytes = b""
    order: int = 0              # the send counter at its last sending (0: not sent)
    sent_at: float = 0.0
    sending: int = 0            # how many times it went out
    answered: bool = False
    seen: bool = False
    ticks: int = 0


@dataclass
class _Model:
    last: int = 0
    sends: int = 0
    order: dict[int, int] = field(default_factory=dict)         # seq -> its last send counter
    motion: dict[int, int] = field(default_factory=dict)        # unanswered motion seq -> frame no.
    requests: dict[int, _Request] = field(default_factory=dict)
    telemetry_seen: bool = False
    data: Param | None = None
    sent: list[int] = field(default_factory=list)


class ExchangeMachine(RuleBasedStateMachine):
    """The exchange against its model (module docstring)."""

    def __init__(self) -> None:
        super().__init__()
        self.ex = Exchange()
        self.m = _Model()
        self.now = 0.0
        self.motion_frames = 0
        self.applied: set[int] = set()          # motion frame numbers ACKed
        self.refused: set[int] = set()          # and NAKed
        self.settled: dict[tuple[int, int], int] = {}   # (seq, sending) -> answers

    @initialize(last=st.one_of(st.just(0), st.integers(SEQ_MAX - 4, SEQ_MAX)))
    def start(self, last: int) -> None:
        """From a fresh counter, or one about to wrap."""
        self.ex = Exchange(memory=4096, max_in_flight=BOUND, last_seq=last)
        self.m.last = last

    # ---- the model's numbering ------------------------------------------------------------
    def _fresh(self) -> int:
        seq = self.m.last % SEQ_MAX + 1
        while seq in self.m.requests:
            seq = seq % SEQ_MAX + 1
        self.m.last = seq
        return seq

    def _register(self, seq: int) -> int:
        self.m.sends += 1
        self.m.order[seq] = self.m.sends
        self.m.sent.append(seq)
        return self.m.sends

    @staticmethod
    def _check_frame(data: bytes, seq: int, body: bytes) -> None:
        assert data == frame(body, seq)
        assert 1 <= seq <= SEQ_MAX
        assert data.endswith(b"\n")
        assert unframe(data[:-1]) == (None, seq, body)     # the firmware's own reading

    # ---- sending --------------------------------------------------------------------------
    @rule(body=st.sampled_from(MOTION))
    def send_motion(self, body: bytes) -> None:
        expected = self._fresh()
        seq, data = self.ex.next_frame(body, motion=True)
        assert seq == expected
        self._check_frame(data, seq, body)
        self._register(seq)
        self.motion_frames += 1
        self.m.motion[seq] = self.motion_frames

    @rule()
    def send_hello(self) -> None:
        expected = self._fresh()
        seq, data = self.ex.next_frame(b"hello:4")
        assert seq == expected
        self._check_frame(data, seq, b"hello:4")
        self._register(seq)

    @rule()
    def take_a_number(self) -> None:
        """The last stop's number: taken, not registered."""
        assert self.ex.next_seq() == self._fresh()

    @rule()
    def open_request(self) -> None:
        if len(self.m.requests) >= BOUND:
            with pytest.raises(InFlightFull):
                self.ex.open()
            return
        expected = self._fresh()
        entry = self.ex.open()
        assert entry.seq == expected
        self.m.requests[entry.seq] = _Request(entry)

    @precondition(lambda self: self.m.requests)
    @rule(data=st.data(), body=st.sampled_from(REQUESTS))
    def send_request(self, data: st.DataObject, body: bytes) -> None:
        """A request goes out, first or again (under its number)."""
        req = self.m.requests[data.draw(st.sampled_from(sorted(self.m.requests)))]
        out = self.ex.send(req.entry, body, self.now)
        self._check_frame(out, req.entry.seq, body)
        req.body, req.order, req.sent_at = body, self._register(req.entry.seq), self.now
        req.sending += 1
        req.answered = req.seen = False
        req.ticks = 0

    @precondition(lambda self: self.m.requests)
    @rule(data=st.data())
    def close_request(self, data: st.DataObject) -> None:
        seq = data.draw(st.sampled_from(sorted(self.m.requests)))
        self.ex.close(self.m.requests.pop(seq).entry)

    @rule(dt=st.sampled_from([0.01, 0.05, 0.2, 0.31]))
    def time_passes(self, dt: float) -> None:
        self.now += dt

    # ---- the board's lines -------------------------------------------------------------------
    def _some_seq(self, data: st.DataObject) -> int:
        """A number the board may name: one in flight, a motion frame's, any sent before
        (repeated, stale), or any at all (0: a board that reset)."""
        pools = [sorted(self.m.requests), sorted(self.m.motion), self.m.sent[-20:]]
        choices = [st.sampled_from(p) for p in pools if p]
        return data.draw(st.one_of(*choices, st.integers(0, SEQ_MAX)))

    @rule(value=st.sampled_from([7.5, 7.2]))
    def data_line(self, value: float) -> None:
        assert self.ex.receive(Param("kp_l", value)) == ()
        self.m.data = Param("kp_l", value)

    @rule()
    def feedback(self) -> None:
        self.ex.end_data()
        self.m.data = None

    @rule(data=st.data(), reason=st.one_of(st.none(), st.sampled_from(REASONS)))
    def answer(self, data: st.DataObject, reason: str | None) -> None:
        seq = self._some_seq(data)
        events = self.ex.receive(Ack(seq) if reason is None else Nak(seq, reason))
        expected: tuple[ExchangeEvent, ...] = ()
        req = self.m.requests.get(seq)
        if req is not None and req.order and not req.answered:
            expected = (Answered(seq, self.m.data, reason),)
            req.answered = True
            key = (seq, req.sending)
            self.settled[key] = self.settled.get(key, 0) + 1
            assert self.settled[key] == 1, "a sending settled twice"
        elif seq in self.m.motion:
            number = self.m.motion.pop(seq)
            if reason is None:
                expected = (MotionApplied(seq),)
                self.applied.add(number)
            else:
                expected = (MotionRefused(seq, reason),)
                self.refused.add(number)
        self.m.data = None
        assert events == expected

    @rule(data=st.data(), estop=st.booleans())
    def telemetry(self, data: st.DataObject, estop: bool) -> None:
        self._tick(self._some_seq(data), estop)

    @rule()
    def telemetry_of_no_frame(self) -> None:
        """A tick of a board that has parsed no frame since it reset (``seq`` 0): it
        reports nothing in flight."""
        self._tick(0, False)

    def _tick(self, seq: int, estop: bool) -> None:
        msg = _telemetry(seq, 4 if estop else 0)
        events = self.ex.receive(msg)
        self.m.telemetry_seen, self.m.data = True, None
        expected = []
        reported = self.m.order.get(seq, 0)
        for req in self.m.requests.values():
            if not req.order or req.answered or req.seen:
                continue
            if seq == req.entry.seq or reported > req.order:
                req.seen = True
                expected.append(Seen(req.entry.seq, msg))
            else:
                req.ticks += 1
        assert events == tuple(expected)
        for event in events:        # seen: by its own number or a frame sent after it
            assert isinstance(event, Seen)
            assert seq == event.seq or reported > self.m.requests[event.seq].order

    @rule()
    def board_resets(self) -> None:
        self.ex.forget_board()
        self.m.telemetry_seen, self.m.data = False, None

    # ---- invariants -------------------------------------------------------------------------
    @invariant()
    def in_flight_is_bounded_and_as_modelled(self) -> None:
        assert len(self.ex.in_flight) <= BOUND
        assert self.ex.in_flight == tuple(self.m.requests)
        assert len(set(self.ex.in_flight)) == len(self.ex.in_flight)
        assert self.ex.last_seq == self.m.last

    @invariant()
    def a_refused_motion_is_never_applied(self) -> None:
        assert not self.applied & self.refused

    @invariant()
    def outcomes_follow_the_lost_answer_rule(self) -> None:
        for req in self.m.requests.values():
            if not req.order:
                continue
            outcome = self.ex.outcome(req.entry, self.now, PATIENCE)
            if req.answered:
                assert outcome is Outcome.ANSWERED
            elif req.seen:
                assert outcome is Outcome.SEEN
            elif self.now - req.sent_at >= PATIENCE and (req.ticks >= 2 or not self.m.telemetry_seen):
                assert outcome is Outcome.LOST
            else:
                assert outcome is Outcome.PENDING


ExchangeMachine.TestCase.settings = settings(max_examples=150, stateful_step_count=60, deadline=None,
                                             suppress_health_check=[HealthCheck.too_slow])
TestExchange = ExchangeMachine.TestCase


# ---- the numbering's edges ------------------------------------------------------------------
def test_the_numbers_wrap_past_seq_max_to_1_never_0() -> None:
    ex = Exchange(last_seq=SEQ_MAX - 1)
    assert [ex.next_frame(b"hello:4")[0] for _ in range(3)] == [SEQ_MAX, 1, 2]


def test_a_fresh_number_goes_round_a_request_still_in_flight() -> None:
    """Once the counter comes round, the number of a request still waiting is skipped:
    its answer must not settle a frame that is not it."""
    ex = Exchange()
    entry = ex.open()                               # number 1, in flight
    for _ in range(SEQ_MAX - 1):
        ex.next_seq()                               # 2 .. SEQ_MAX
    seq, _ = ex.next_frame(b"x:0.000,t:0.000,", motion=True)
    assert (entry.seq, seq) == (1, 2)
    ex.close(entry)
    assert ex.next_seq() == 3


def test_the_motion_frames_awaiting_an_answer_are_bounded() -> None:
    """The oldest unanswered motion frames are forgotten beyond ``memory``: their late
    answers are no event."""
    ex = Exchange(memory=4)
    seqs = [ex.next_frame(b"x:0.000,t:0.000,", motion=True)[0] for _ in range(6)]
    assert ex.receive(Nak(seqs[0], "range")) == ()
    assert ex.receive(Nak(seqs[-1], "range")) == (MotionRefused(seqs[-1], "range"),)


# ---- the verdicts -------------------------------------------------------------------------------
def _answered(ex: Exchange, body: bytes, *lines: object) -> InFlight:
    entry = ex.open()
    ex.send(entry, body, 0.0)
    for line in lines:
        ex.receive(line)
    return entry


def test_an_answer_is_judged_by_its_kind() -> None:
    ex = Exchange()
    got = _answered(ex, b"get:kp_l", Param("kp_l", 7.2), Ack(1))
    assert answer_verdict("get", "kp_l", got).next is Next.RETURN
    assert answer_verdict("get", "kp_l", got).value == Param("kp_l", 7.2)
    bare = _answered(ex, b"get:kp_l", Ack(2))                   # its PAR: line was lost
    assert answer_verdict("get", "kp_l", bare).next is Next.ASK_AGAIN
    assert answer_verdict("set", "kp_l", bare).next is Next.READ_BACK
    refused = _answered(ex, b"x", Nak(3, "estop"))
    assert answer_verdict("set", "kp_l", refused) == answer_verdict("reset", "", refused)
    assert answer_verdict("reset", "", refused).reason == "estop"
    assert answer_verdict("save", "", _answered(ex, b"save", Ack(4))).next is Next.RETURN


@pytest.mark.parametrize(("word", "estop", "expected"), [
    ("estop", True, Next.RETURN), ("estop", False, Next.SEND_AGAIN),
    ("reset", False, Next.RETURN), ("reset", True, Next.REFUSED),
    ("get", False, Next.ASK_AGAIN), ("set", False, Next.CHECK_BACK),
    ("save", False, Next.SEND_AGAIN), ("defaults", True, Next.SEND_AGAIN)])
def test_a_lost_answer_is_read_from_the_board_as_its_kind_says(word: str, estop: bool,
                                                               expected: Next) -> None:
    assert lost_answer_verdict(word, _telemetry(5, 4 if estop else 0)).next is expected


def test_a_set_read_back_is_done_only_at_the_value_asked_for() -> None:
    assert read_back_verdict(b"7.5", Param("kp_l", 7.5)).next is Next.RETURN
    assert read_back_verdict(b"7.5", Param("kp_l", 7.2)).next is Next.SEND_AGAIN
    assert read_back_verdict(b"7.5", None).next is Next.SEND_AGAIN
