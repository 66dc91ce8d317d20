"""``FaultyPort``: a ``Port`` whose link loses, garbles and delays what goes through,
goes dead or is unplugged, on request and reproducibly (seeded), for tests.

    port = FaultyPort(serial.serial_for_url("wcsim://"), seed=1)
    port.rx.drop(match=rb"^ACK:", count=1)    # the board's next ACK never arrives
    port.tx.flip(bits=1, rate=0.01)           # 1 % of the host's writes get a flipped bit
    port.rx.delay(0.2)                        # the board's lines arrive 0.2 s late
    port.cut()                                # the link is dead both ways ...
    port.restore()                            # ... and back
    port.unplug(); port.replug()              # meanwhile reads and writes raise
    chair = wcdrive.Wheelchair(port)

``tx`` is what the host writes, judged a write at a time (the session writes a line
at a time); ``rx`` is what the board sends, judged a line at a time once its ``\\n``
came. Each fault is a ``Rule``: it acts on the units that its ``match`` (a regex)
finds, each with probability ``rate``, ``count`` times at most, and keeps what it did
in ``hits``. The rules of a direction apply in the order they were added.

The random choices (``rate`` < 1, the bits a flip picks, where a cut write ends) come
from one ``random.Random`` (``seed``, or one given), drawn only where a rule applies,
so a run with the same seed and the same traffic injects the same faults. Delays are
on ``clock`` (``time.monotonic``; a stepped test passes its own).
"""

from __future__ import annotations

import random
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from serial import PortNotOpenError, SerialException

from wcdrive.transports.port import Port
from wcdrive.transports.wrapper import PortWrapper

__all__ = ["Direction", "FaultyPort", "Rule"]

#: What pyserial's posix port raises when a USB device goes away under it.
UNPLUGGED = ("device reports readiness to read but returned no data "
             "(device disconnected or multiple access on port?)")

Pattern = bytes | re.Pattern[bytes] | None


@dataclass
class Rule:
    """One fault of a direction. ``kind``: ``drop`` (the unit is lost), ``flip``
    (``bits`` distinct bits flipped: within the match's group 1 when the pattern has
    one, else anywhere but the line end ``\\r\\n``), ``delay`` (the unit and what
    follows it wait ``seconds``) or ``edit`` (``edit(unit)`` instead; None drops it).
    ``count``: how many more units it acts on (None: no limit). ``hits``: (the unit,
    what became of it: None when dropped), in order."""

    kind: str
    match: re.Pattern[bytes] | None = None
    rate: float = 1.0
    count: int | None = None
    bits: int = 1
    seconds: float = 0.0
    edit: Callable[[bytes], bytes | None] | None = None
    hits: list[tuple[bytes, bytes | None]] = field(default_factory=list)


class Direction:
    """The faults of one direction of a ``FaultyPort`` (``tx`` or ``rx``): its
    ``rules``, whether it is ``cut`` (everything lost), and ``passed``, the bytes that
    got through."""

    def __init__(self, owner: FaultyPort) -> None:
        self._owner = owner
        self.rules: list[Rule] = []
        self.cut = False
        self.passed = 0

    def _add(self, rule: Rule) -> Rule:
        with self._owner.lock:
            self.rules.append(rule)
        return rule

    def drop(self, rate: float = 1.0, *, match: Pattern = None, count: int | None = None) -> Rule:
        """Loses units."""
        return self._add(Rule("drop", _compile(match), rate, count))

    def flip(self, bits: int = 1, rate: float = 1.0, *, match: Pattern = None,
             count: int | None = None) -> Rule:
        """Flips ``bits`` bits of units (a corrupted byte on the wire)."""
        return self._add(Rule("flip", _compile(match), rate, count, bits=bits))

    def delay(self, seconds: float, rate: float = 1.0, *, match: Pattern = None,
              count: int | None = None) -> Rule:
        """Holds units back ``seconds``; the link keeps its order, so what follows a
        late unit comes no earlier. A held write goes out at the port's first call
        (any method) at or after its time, a held line with the first read."""
        return self._add(Rule("delay", _compile(match), rate, count, seconds=seconds))

    def edit(self, edit: Callable[[bytes], bytes | None], *, match: Pattern = None,
             count: int | None = None) -> Rule:
        """Replaces units with ``edit(unit)`` (None: lost)."""
        return self._add(Rule("edit", _compile(match), 1.0, count, edit=edit))

    def clear(self) -> None:
        """Removes every rule (a cut stays)."""
        with self._owner.lock:
            self.rules.clear()

    def _apply(self, unit: bytes) -> tuple[bytes | None, float]:
        """``unit`` through the rules (the caller holds the lock): what is left of it
        (None: lost) and how long it is held back."""
        rng = self._owner.rng
        held = 0.0
        out: bytes | None = unit
        for rule in self.rules:
            if out is None:
                break
            m = rule.match.search(out) if rule.match is not None else None
            if rule.match is not None and m is None:
                continue
            if rule.count is not None and rule.count <= 0:
                continue
            if rule.rate < 1.0 and rng.random() >= rule.rate:
                continue
            before = out
            if rule.kind == "drop":
                out = None
            elif rule.kind == "flip":
                out = _flip(out, m, rule.bits, rng)
            elif rule.kind == "delay":
                held += rule.seconds
            elif rule.edit is not None:
                out = rule.edit(out)
            if rule.count is not None:
                rule.count -= 1
            rule.hits.append((before, out))
        return out, held


def _compile(match: Pattern) -> re.Pattern[bytes] | None:
    return re.compile(match) if isinstance(match, bytes) else match


def _flip(unit: bytes, m: re.Match[bytes] | None, bits: int, rng: random.Random) -> bytes:
    if m is not None and m.re.groups and m.start(1) >= 0:
        start, end = m.span(1)
    else:
        start, end = 0, len(unit.rstrip(b"\r\n"))
    positions = rng.sample(range(8 * start, 8 * end), min(bits, 8 * (end - start)))
    out = bytearray(unit)
    for p in positions:
        out[p // 8] ^= 0x80 >> (p % 8)
    return bytes(out)


class FaultyPort(PortWrapper):
    """A ``Port`` around ``port`` with faults on the link: ``tx`` and ``rx`` (each a
    ``Direction``: ``drop``, ``flip``, ``delay``, ``edit``), ``cut``/``restore`` (the
    link dead, both ways or one) and ``unplug``/``replug`` (the device gone).

    - With no rule and no cut on ``rx``, the board's bytes pass as they come; else,
      and always with ``lines``, whole lines (a line is held until its ``\\n`` came).
    - Cut: the bytes are lost while the port stays open and calls return as usual;
      with rules on ``rx`` or ``lines``, whole lines (one whose ``\\n`` comes after the
      ``restore`` arrives whole, as if the cut had come between lines).
      ``cut(partial=True)``: the next write, if longer than a byte, hands only a random
      head of itself (1 .. len-1 bytes) to the board, as when the cable goes mid-line.
    - Unplugged: ``read``, ``write``, ``flush`` and ``in_waiting`` raise
      ``SerialException`` (pyserial's message for a vanished USB device), a read
      blocked meanwhile too; what the board sent is lost, up to the ``replug``.
    - ``read(size)`` returns fewer than ``size`` bytes only once the wrapped port's
      timeout passed, as pyserial's; what a line gave beyond ``size`` waits for the
      next read.

    What the wrapped port read reaches ``on_read`` before the faults: a subclass that
    overrides it sees every byte the board sent (and calls ``super().on_read``).
    """

    def __init__(self, port: Port, seed: int | random.Random = 0,
                 clock: Callable[[], float] = time.monotonic, lines: bool = False) -> None:
        super().__init__(port)
        self.lines = lines
        self.rng = seed if isinstance(seed, random.Random) else random.Random(seed)
        self.clock = clock
        self._lock = threading.RLock()
        self.tx = Direction(self)
        self.rx = Direction(self)
        self.unplugged = False
        self._cut_partial = False
        self._partial = bytearray()                          # rx: a line under way
        self._rx_held: deque[tuple[float, bytes]] = deque()  # rx: lines delayed
        self._ready = bytearray()                            # rx: for the next reads
        self._tx_held: deque[tuple[float, bytes]] = deque()  # tx: writes delayed

    # ---- faults of the link -----------------------------------------------------------
    @property
    def lock(self) -> threading.RLock:
        """Held around the rules, the random draws and the buffers (the directions'
        ``tx``/``rx`` take it too)."""
        return self._lock

    def cut(self, tx: bool = True, rx: bool = True, partial: bool = False) -> None:
        """The link goes dead: what the host writes (``tx``) and what the board sends
        (``rx``) are lost; ``partial``: the next write goes out in part."""
        with self._lock:
            self.tx.cut = self.tx.cut or tx
            self.rx.cut = self.rx.cut or rx
            self._cut_partial = partial and tx
            if rx:                              # what was on its way is lost too
                self._ready.clear()
                self._rx_held.clear()

    def restore(self) -> None:
        """Ends a cut, both ways."""
        with self._lock:
            self.tx.cut = self.rx.cut = False
            self._cut_partial = False

    def unplug(self) -> None:
        """The device vanishes: calls raise until ``replug``."""
        with self._lock:
            self.unplugged = True
            self._partial.clear()
            self._ready.clear()
            self._rx_held.clear()
            self._tx_held.clear()

    def replug(self) -> bytes:
        """The device is back. What the board sent meanwhile is lost: returns the
        bytes of it that the wrapped port still held (they went to ``on_read`` too)."""
        with self._lock:
            waiting = self.port.in_waiting
            lost = self.port.read(waiting) if waiting else b""
            self.on_read(lost)                  # still unplugged: nothing passes
            self.unplugged = False
        return lost

    def _check(self) -> None:
        if self.unplugged:
            raise SerialException(UNPLUGGED)

    # ---- the host's side: tx --------------------------------------------------------------
    def on_write(self, data: bytes) -> bytes:
        """``data`` through the cut and the ``tx`` rules: what goes to the board now."""
        self._check()
        self._release()
        with self._lock:
            if self.tx.cut:
                partial, self._cut_partial = self._cut_partial, False
                if partial and len(data) > 1:
                    return data[:self.rng.randrange(1, len(data))]
                return b""
            out, held = self.tx._apply(data)
            if out is None:
                return b""
            if held > 0 or self._tx_held:
                self._tx_held.append((self.clock() + held, out))
                return b""
            return out

    def on_sent(self, data: bytes) -> None:
        """Counts ``data`` in ``tx.passed``."""
        with self._lock:
            self.tx.passed += len(data)

    def _release(self) -> None:
        """Writes the delayed writes that are due."""
        while True:
            with self._lock:
                if not self._tx_held or self._tx_held[0][0] > self.clock():
                    return
                _, data = self._tx_held.popleft()
            self.port.write(data)
            self.on_sent(data)

    def flush(self) -> None:
        """Sends the due delayed writes and flushes the wrapped port."""
        self._check()
        self._release()
        self.port.flush()

    # ---- the board's side: rx -------------------------------------------------------------
    def _passing(self) -> bool:
        return not (self.lines or self.rx.rules or self.rx.cut or self._partial or self._rx_held)

    def on_read(self, data: bytes) -> bytes:
        """``data``, read from the wrapped port, through the cut and the ``rx`` rules:
        what the host gets of it now (lines held back come later)."""
        with self._lock:
            if self.unplugged:
                return b""
            if self.rx.cut:
                if self.lines or self.rx.rules:     # lose whole lines, keep the tail
                    self._partial += data
                    del self._partial[:self._partial.rfind(b"\n") + 1]
                else:
                    self._partial.clear()
                return b""
            if self._passing():
                self.rx.passed += len(data)
                return data
            self._partial += data
            end = self._partial.rfind(b"\n") + 1
            lines = bytes(self._partial[:end]).splitlines(keepends=True)
            del self._partial[:end]
            now = self.clock()
            for line in lines:
                out, held = self.rx._apply(line)
                if out is not None:
                    self._rx_held.append((now + held, out))
            return self._due()

    def _due(self) -> bytes:
        """The held lines whose time has come, in order (the caller holds the lock)."""
        out = bytearray()
        now = self.clock()
        while self._rx_held and self._rx_held[0][0] <= now:
            out += self._rx_held.popleft()[1]
        self.rx.passed += len(out)
        return bytes(out)

    @property
    def in_waiting(self) -> int:
        """Bytes the next read returns at once, at most (those of lines that will be
        lost included)."""
        self._check()
        self._release()
        with self._lock:
            ready = len(self._ready)
            if self.rx.cut:
                return ready
        return ready + int(self.port.in_waiting)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, as the wrapped port reads them: fewer only once its
        ``timeout`` passed (with lines held back, a read may wait up to about twice it)."""
        self._check()
        if not self.is_open:                    # what was read ahead is gone with the port
            raise PortNotOpenError()
        self._release()
        timeout = self.port.timeout
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            with self._lock:
                self._ready += self._due()
                if len(self._ready) >= size:
                    break
                want = size - len(self._ready)
                passing = self._passing()
            if not passing:        # whole lines: what has come, so as not to end mid-line
                want = max(want, int(self.port.in_waiting))
            data = self.port.read(want)
            got = self.on_read(data)
            self._check()
            with self._lock:
                self._ready += got
            if len(data) < want:                            # its timeout passed
                break
            if deadline is not None and time.monotonic() >= deadline:
                break
        with self._lock:
            self._ready += self._due()
            out = bytes(self._ready[:size])
            del self._ready[:size]
        return out
