"""The host's half of the request/answer exchange, without I/O: one numbering of the
frames and one rule for their answers, for every host that frames its commands.

``Exchange`` is a plain state machine, in the manner of h11 and wsproto: no thread, no
clock, no port. The caller hands it what the board said and the time as a number, and
writes the bytes it returns::

    ex = Exchange()
    seq, data = ex.next_frame(b"x:0.500,t:0.100,", motion=True)  # 1, b"$1:x:0.500,...*XXXX\\n"
    entry = ex.open()                          # a request in flight, under number 2
    data = ex.send(entry, b"get:...", now)     # its frame, going out now (again, later)
    ex.receive(Param(name, value))             # the data line the ACK answers with
    ex.receive(Ack(2))                         # -> (Answered(2, Param(...), None),)
    ex.outcome(entry, now, patience)           # Outcome.ANSWERED
    answer_verdict("get", name, entry)         # Verdict(Next.RETURN, Param(...))
    ex.close(entry)

Numbering: every frame takes its number from one counter, 1 to ``SEQ_MAX`` and round
again (a board that reset reports 0, so 0 is never used), skipping the numbers of the
requests still in flight. The counter also keeps the send order of the last ``memory``
frames.

Answers: an ``ACK:``/``NAK:`` settles the request in flight under its number once per
sending (``Answered``, with the data line just before it); for a motion frame that was
sent and not answered yet, a ``NAK:`` is ``MotionRefused`` and an ``ACK:``
``MotionApplied``, once. Any other answer (a stale or repeated number, the hello's) is
no event. A ``TLM:`` line reports the last number the board parsed: each request sent
no later than that frame is ``Seen`` (the board has it; its answer, if none came, was
lost), the others count a tick.

Lost answers (``Exchange.outcome``, then the verdicts): a request neither answered nor
seen ``patience`` seconds after it went out, with two ``TLM:`` lines since that do not
report it (on a board that sends none, after ``patience`` alone), is ``LOST``: the board
did not get it, and it may go out again under its number. A request seen but not
answered is read back as its kind says (``lost_answer_verdict``): an e-stop from the
TLM's e-stop flag, a reset likewise (the board refuses a reset only while it is not
parked), a get is asked again under a new number, a set is read back and sent again
only when the value in force is not the one asked for, and the rest (save, defaults)
is sent again.

Why this way: the board acts on every frame it parses, a repeated one too, so a request
may go out again only when the board shows that it did not get it, and the proof is the
send order: one counter numbers every frame (the hello, motion, requests), so a ``TLM:``
line that reports a later frame proves that an earlier one arrived. The rules live here
once: ``wcdrive.host.tracker.RequestTracker`` (threads, waiting, the port) judges every
answer by them, and it and ``wcdrive.testing.stepped.SteppedChair`` (simulated time, no
answer awaited) number their frames from an ``Exchange`` alike.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from wcdrive.errors import WcdriveError
from wcdrive.protocol.codec import SEQ_MAX, Ack, ExtendedTelemetry, Feedback, Hello, Nak, Param, frame

__all__ = [
    "MEMORY", "Answered", "Exchange", "ExchangeEvent", "InFlight", "InFlightFull",
    "MotionApplied", "MotionRefused", "Next", "Outcome", "Seen", "Verdict", "answer_verdict",
    "lost_answer_verdict", "read_back_verdict", "same_value",
]

#: How many recent frames keep their send order, and how many motion frames await an
#: answer; also the most requests in flight at once.
MEMORY = 256

#: The data lines an ``ACK:`` answers with (it follows the line at once).
DataLine = Hello | Param


class InFlightFull(WcdriveError, RuntimeError):
    """``Exchange.open`` with ``max_in_flight`` requests open already: some caller
    opens requests and never closes them."""


# ---- what receive() settles ------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Answered:
    """The request ``seq`` was answered: ``ACK:`` (``reason`` None) with ``data``, the
    data line just before it (``PAR:``, ``HELLO:``; None when none came), or ``NAK:``
    with its ``reason``."""

    seq: int
    data: DataLine | None
    reason: str | None


@dataclass(frozen=True, slots=True)
class MotionApplied:
    """The motion frame ``seq`` was ``ACK``ed: the board took it."""

    seq: int


@dataclass(frozen=True, slots=True)
class MotionRefused:
    """The motion frame ``seq`` was ``NAK``ed with ``reason``: the board did not take it."""

    seq: int
    reason: str


@dataclass(frozen=True, slots=True)
class Seen:
    """A ``TLM:`` line shows that the board parsed the request ``seq`` (its number, or
    a later frame's): its answer, if none came, was lost."""

    seq: int
    telemetry: ExtendedTelemetry


ExchangeEvent = Answered | MotionApplied | MotionRefused | Seen


class Outcome(enum.Enum):
    """Where a request in flight stands (``Exchange.outcome``)."""

    PENDING = "pending"     # no word yet
    ANSWERED = "answered"   # its ACK/NAK came
    SEEN = "seen"           # the board has it, its answer was lost
    LOST = "lost"           # the board did not get it: it may go out again


class InFlight:
    """A request in flight. Read its fields; only its ``Exchange`` changes them."""

    __slots__ = ("answered", "data", "order", "reason", "seen", "sent_at", "seq", "ticks")

    def __init__(self, seq: int) -> None:
        self.seq = seq
        self.answered = False
        self.data: DataLine | None = None
        self.reason: str | None = None
        #: The exchange's send counter when it last went out (0: not yet).
        self.order = 0
        #: The caller's time of that send.
        self.sent_at = 0.0
        #: ``TLM:`` lines since then that do not report it.
        self.ticks = 0
        #: The first ``TLM:`` line that reports it (its number, or a later frame's).
        self.seen: ExtendedTelemetry | None = None


# ---- the verdicts: what the caller does next -------------------------------------------
class Next(enum.Enum):
    """What to do with a request whose outcome is known (``Verdict.next``)."""

    RETURN = "return"           # done: its result is ``Verdict.value``
    REFUSED = "refused"         # the board refused it: ``Verdict.reason``
    SEND_AGAIN = "send again"   # the board did not act on it: send it again, same number
    ASK_AGAIN = "ask again"     # a get whose answer was lost: a new request, a new number
    READ_BACK = "read back"     # a set that was done, its data line lost: the result is a get's
    CHECK_BACK = "check back"   # a set whose answer was lost: a get, then read_back_verdict


@dataclass(frozen=True, slots=True)
class Verdict:
    """``next``, with the result (``value``) or the board's ``reason``."""

    next: Next
    value: object | None = None
    reason: str | None = None


#: The requests (by their word on the wire) whose answer carries a ``PAR:`` line.
_PARAM_WORDS = ("get", "set")


def same_value(value: float, text: bytes) -> bool:
    """Whether ``value`` (as the board prints a parameter: 4 decimals) is ``text``."""
    try:
        wanted = float(text)
    except ValueError:
        return False
    return abs(value - wanted) <= 0.5e-4 + 1e-6 * abs(wanted)


def answer_verdict(word: str, param: str, entry: InFlight) -> Verdict:
    """The verdict on the request ``entry``, answered, whose word on the wire is
    ``word`` (``get``, ``set``, ``save``, ``defaults``, ``estop``, ``reset``) about
    the parameter ``param`` (get and set): a ``NAK:`` refuses; a get or set whose
    ``PAR:`` line did not come with its ``ACK:`` (lost on the way) is asked again (a
    get) or read back (a set: the board did set it); else its data line is the result."""
    if entry.reason is not None:
        return Verdict(Next.REFUSED, reason=entry.reason)
    if word in _PARAM_WORDS:
        data = entry.data
        if not isinstance(data, Param) or data.name != param:
            return Verdict(Next.READ_BACK if word == "set" else Next.ASK_AGAIN)
    return Verdict(Next.RETURN, entry.data)


def lost_answer_verdict(word: str, seen: ExtendedTelemetry) -> Verdict:
    """The verdict on a request the board parsed (the ``TLM:`` line ``seen`` says so)
    but whose answer was lost, read from the board rather than acted on twice: an
    e-stop is done when ``seen`` shows it latched (else sent again); a reset is done
    unless the e-stop is still latched (the board refuses a reset, ``busy``, only
    while the chair is not parked); a get is asked again; a set is checked by reading
    it back; save and defaults go out again."""
    if word == "estop":
        return Verdict(Next.RETURN) if seen.estop_latched else Verdict(Next.SEND_AGAIN)
    if word == "reset":
        return Verdict(Next.REFUSED, reason="busy") if seen.estop_latched else Verdict(Next.RETURN)
    if word == "get":
        return Verdict(Next.ASK_AGAIN)
    if word == "set":
        return Verdict(Next.CHECK_BACK)
    return Verdict(Next.SEND_AGAIN)


def read_back_verdict(text: bytes, current: object | None) -> Verdict:
    """After ``Next.CHECK_BACK``: the set of ``text`` is done when the value read back
    (``current``) is it, else it goes out again."""
    if isinstance(current, Param) and same_value(current.value, text):
        return Verdict(Next.RETURN, current)
    return Verdict(Next.SEND_AGAIN)


def _remember(recent: dict[int, int | None], seq: int, value: int | None, memory: int) -> None:
    """Notes ``seq`` as the newest of ``recent``, which keeps the last ``memory``."""
    recent.pop(seq, None)
    recent[seq] = value
    if len(recent) > memory:
        del recent[next(iter(recent))]


class Exchange:
    """The numbering and the answer bookkeeping of one link (module docstring).

    ``memory``: how many recent frames keep their send order, and how many motion
    frames await an answer; ``max_in_flight``: the most requests open at once
    (``open`` raises ``InFlightFull`` beyond); ``last_seq``: the number given out last
    (the first frame takes the one after it). Not thread-safe: a caller on several
    threads holds one lock around every call."""

    def __init__(self, *, memory: int = MEMORY, max_in_flight: int = MEMORY, last_seq: int = 0) -> None:
        if memory < 1 or not 1 <= max_in_flight < SEQ_MAX or not 0 <= last_seq <= SEQ_MAX:
            raise ValueError("memory must be >= 1, max_in_flight in 1 .. SEQ_MAX - 1 and "
                             "last_seq in 0 .. SEQ_MAX")
        self.memory = memory
        self.max_in_flight = max_in_flight
        self._seq = last_seq
        self._sends = 0
        self._sent_order: dict[int, int | None] = {}    # seq -> the send counter when it went out
        self._motion: dict[int, int | None] = {}        # motion frames not answered yet
        self._requests: dict[int, InFlight] = {}
        self._last_data: DataLine | None = None        # a data line, until the ACK it comes with
        self._telemetry_seen = False

    # ---- numbering -----------------------------------------------------------------------
    @property
    def last_seq(self) -> int:
        """The number last given out (0 before the first)."""
        return self._seq

    def next_seq(self) -> int:
        """A fresh number, 1 .. ``SEQ_MAX`` and round again, none of a request still in
        flight. Not registered in the send order: for a frame whose answer nobody
        awaits and that proves nothing (the last stop)."""
        seq = self._seq % SEQ_MAX + 1
        while seq in self._requests:
            seq = seq % SEQ_MAX + 1
        self._seq = seq
        return seq

    def _register(self, seq: int) -> int:
        self._sends += 1
        _remember(self._sent_order, seq, self._sends, self.memory)
        return self._sends

    def next_frame(self, body: bytes, *, motion: bool = False) -> tuple[int, bytes]:
        """``body`` as a frame under a fresh number, going out now (registered in the send
        order): (the number, the frame's bytes). A ``motion`` frame's answer is an event
        (``MotionApplied``, ``MotionRefused``); any other's is none."""
        seq = self.next_seq()
        self._register(seq)
        if motion:
            _remember(self._motion, seq, None, self.memory)
        return seq, frame(body, seq)

    # ---- requests --------------------------------------------------------------------------
    @property
    def in_flight(self) -> tuple[int, ...]:
        """The numbers of the requests open, oldest first."""
        return tuple(self._requests)

    def open(self) -> InFlight:
        """A request under a fresh number, in flight until ``close``; ``send`` puts it on
        the wire. Raises ``InFlightFull`` when ``max_in_flight`` are open already."""
        if len(self._requests) >= self.max_in_flight:
            raise InFlightFull(f"{len(self._requests)} requests in flight already: "
                               "each opened request must be closed")
        entry = InFlight(self.next_seq())
        self._requests[entry.seq] = entry
        return entry

    def send(self, entry: InFlight, body: bytes, now: float) -> bytes:
        """The frame of the request ``entry`` with the command ``body``, going out now
        (at the caller's time ``now``, first or again, under its number): what was known
        of an earlier sending is forgotten."""
        data = frame(body, entry.seq)
        entry.order, entry.sent_at = self._register(entry.seq), now
        entry.ticks, entry.seen = 0, None
        entry.answered, entry.data, entry.reason = False, None, None
        return data

    def close(self, entry: InFlight) -> None:
        """``entry`` is settled or given up: an answer to it from now on is stale."""
        if self._requests.get(entry.seq) is entry:
            del self._requests[entry.seq]

    def outcome(self, entry: InFlight, now: float, patience: float) -> Outcome:
        """Where ``entry`` stands at ``now``: answered, seen, lost (neither, ``patience``
        s after it went out, with two ``TLM:`` lines since that do not report it, or no
        ``TLM:`` line at all from this board), or pending."""
        if entry.answered:
            return Outcome.ANSWERED
        if entry.seen is not None:
            return Outcome.SEEN
        if now - entry.sent_at >= patience and (entry.ticks >= 2 or not self._telemetry_seen):
            return Outcome.LOST
        return Outcome.PENDING

    # ---- the board's lines ---------------------------------------------------------------
    def receive(self, msg: object) -> tuple[ExchangeEvent, ...]:
        """One message from the board, in the order they came; returns what it settles.
        ``Hello`` and ``Param`` are the data of the ``ACK:`` that follows them at once;
        ``Ack``/``Nak`` settle a request or a motion frame; ``ExtendedTelemetry``
        reports the last number the board parsed; it and ``Feedback`` (the lines of a
        tick, which never come between a data line and its ``ACK:``) drop a data line
        still unanswered. Other messages change nothing."""
        if isinstance(msg, (Hello, Param)):
            self._last_data = msg
            return ()
        if isinstance(msg, (Ack, Nak)):
            return self._answer(msg)
        if isinstance(msg, ExtendedTelemetry):
            self._last_data = None
            return self._telemetry(msg)
        if isinstance(msg, Feedback):
            self.end_data()
        return ()

    def end_data(self) -> None:
        """A line that is no data line came (feedback): a data line before it answers
        no ``ACK:``."""
        self._last_data = None

    def _answer(self, msg: Ack | Nak) -> tuple[ExchangeEvent, ...]:
        data, self._last_data = self._last_data, None
        reason = msg.reason if isinstance(msg, Nak) else None
        entry = self._requests.get(msg.seq)
        if entry is not None and entry.order and not entry.answered:
            entry.answered, entry.data, entry.reason = True, data, reason
            return (Answered(msg.seq, data, reason),)
        if msg.seq in self._motion:
            del self._motion[msg.seq]
            return (MotionApplied(msg.seq),) if reason is None else (MotionRefused(msg.seq, reason),)
        return ()

    def _telemetry(self, msg: ExtendedTelemetry) -> tuple[ExchangeEvent, ...]:
        self._telemetry_seen = True
        reported = self._sent_order.get(msg.seq) or 0
        seen: list[ExchangeEvent] = []
        for entry in self._requests.values():
            if entry.order == 0 or entry.answered or entry.seen is not None:
                continue
            if msg.seq == entry.seq or reported > entry.order:
                entry.seen = msg
                seen.append(Seen(entry.seq, msg))
            else:
                entry.ticks += 1
        return tuple(seen)

    def forget_board(self) -> None:
        """The board has reset: a data line of the old one answers nothing, and its
        ``TLM:`` lines are yet to come."""
        self._last_data = None
        self._telemetry_seen = False
