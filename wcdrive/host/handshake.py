"""The hello handshake: up to three framed hellos, each waiting twice as long as the one
before, and what the board's answer says (protocol version, firmware, build id).

``Handshake.step`` says hello when the board first speaks and again when a hello was
refused or went unanswered for its wait; after the third it gives up (protocol v1 in
legacy mode, else ``error``). ``answered`` takes the board's ``HELLO:`` line. ``done``
is set once the handshake is over, either way.

Why the pacing: a hello may be lost or garbled (the reset on open cuts a line in two),
and a board busy booting answers late; a refused hello goes out again only a tick
later, since the board answers at most 3 frames a tick.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from wcdrive.errors import WcdriveConnectionError, WcdriveProtocolError
from wcdrive.protocol.codec import Hello
from wcdrive.protocol.spec import integer

__all__ = ["HELLO_COMMAND", "PROTOCOL_VERSION", "Handshake"]

#: The protocol this host speaks, the spec's (``connect(url, legacy=True)`` also speaks v1).
PROTOCOL_VERSION = integer("PROTOCOL_VERSION")
#: The hello this host says: ``hello:4`` asks the board to frame its lines.
HELLO_COMMAND = b"hello:%d" % PROTOCOL_VERSION

_log = logging.getLogger("wcdrive.session")


class Handshake:
    """The handshake with the board named ``name``. ``say_hello`` sends one hello frame
    and returns its sequence number (``WcdriveConnectionError`` when the link is
    down: that hello counts as sent). ``legacy``: after three unanswered hellos, the
    board speaks protocol v1. ``on_greeted`` runs when the board's first answer of a
    handshake arrives, before ``done`` is set.

    ``lock`` guards the hello's pacing; ``step`` is called by the reader thread and by
    the link monitor."""

    #: How long each hello waits for its answer before the next goes out: 3 tries,
    #: each waiting twice as long as the one before.
    HELLO_WAITS = (0.25, 0.5, 1.0)
    #: A refused hello is said again this long after the last, at the soonest: the next
    #: tick's answer budget (benchmarks/reliability.py R3 saw three ERR lines of a frame
    #: cut by a reset spend one, and the hellos sent at once went unanswered).
    HELLO_REFUSED_GAP = 0.06

    def __init__(self, name: str, say_hello: Callable[[], int], on_greeted: Callable[[], None],
                 *, legacy: bool = False) -> None:
        self.name = name
        self.legacy = legacy
        self._say = say_hello
        self._on_greeted = on_greeted
        self.lock = threading.Lock()
        #: Set once the handshake is over: answered, failed, or legacy.
        self.done = threading.Event()
        #: The protocol the board speaks: 4 once it answered hello, 1 in legacy mode
        #: once three hellos went unanswered, 0 until then.
        self.protocol_version = 0
        self.firmware = ""
        self.firmware_version = ""
        self.build_id = ""
        #: Why the handshake failed, or None.
        self.error: WcdriveProtocolError | None = None
        self._tries = 0                 # hellos sent since the board (re)started
        self._sent_at = 0.0
        self._seq = -1
        self._rejected = False          # the board refused the last hello (ERR/NAK)

    def _say_hello(self, now: float) -> None:
        """Sends the next hello. Under ``lock``."""
        self._tries += 1
        self._sent_at = now
        self._rejected = False
        try:
            self._seq = self._say()
        except WcdriveConnectionError:
            pass

    def step(self, now: float, *, first: bool = False) -> float:
        """Says hello when the board first speaks (``first``), again when the last hello
        was refused (a garbled frame: ``ERR:``/``NAK:``) or went unanswered for its
        wait, and ends the handshake after the third. Returns how long the link monitor
        may sleep before it needs to look again."""
        with self.lock:
            if self.done.is_set():
                return 0.05
            if self._tries == 0:
                if first:
                    self._say_hello(now)
                    return self.HELLO_WAITS[0]
                return 0.05
            left = self._sent_at + self.HELLO_WAITS[self._tries - 1] - now
            if left > 0 and not self._rejected:
                return left
            # A refused hello goes out again no sooner than a tick later: the board answers
            # 3 commands a tick, and the ERR lines of a frame cut by a reset can spend them.
            soon = self._sent_at + self.HELLO_REFUSED_GAP - now
            if soon > 0:
                return soon
            if self._tries < len(self.HELLO_WAITS):
                self._say_hello(now)
                return self.HELLO_WAITS[self._tries - 1]
            if self.legacy:
                _log.info("%s: no answer to hello: driving it as a protocol-v1 board", self.name)
                self.protocol_version = 1
            else:
                self.error = WcdriveProtocolError(
                    f"{self.name} did not answer hello ({self._tries} tries): it is not "
                    f"running protocol-v{PROTOCOL_VERSION} firmware. Flash it (wcdrive bench "
                    "flash), or connect(url, legacy=True) to drive a protocol-v1 board "
                    "without checksums, e-stop, parameters or telemetry")
            self.done.set()
            return 0.05

    def answered(self, msg: Hello) -> None:
        """The board's ``HELLO:`` line: the handshake is over (a version this host does
        not know fails it)."""
        if msg.version != PROTOCOL_VERSION:
            if self.protocol_version == PROTOCOL_VERSION:
                return                          # a stray line; the board said v3 already
            self.error = WcdriveProtocolError(
                f"{self.name} speaks protocol v{msg.version} ({msg.firmware} "
                f"{msg.firmware_version}), which this wcdrive does not know: it speaks "
                f"v{PROTOCOL_VERSION}. Flash the firmware that comes with it "
                "(wcdrive bench flash) or install the wcdrive that matches the board")
            self.done.set()
            return
        self.protocol_version = msg.version
        self.error = None
        self.firmware, self.firmware_version, self.build_id = (
            msg.firmware, msg.firmware_version, msg.build_id)
        _log.info("%s: connected, protocol v%d, %s %s", self.name, msg.version, msg.firmware,
                  msg.firmware_version)
        if not self.done.is_set():
            self._on_greeted()
        self.done.set()

    def note_answer(self, now: float, nak_seq: int | None, reason: str = "") -> None:
        """An ``ACK:`` or ``NAK:`` came; ``nak_seq``: the number of a ``NAK:`` no request
        claimed (None otherwise), which refuses the last hello when it is its number. A
        refused hello goes out again as soon as it may, but for one the board does not
        know (``syntax``: its firmware is older than v4), which ends the handshake."""
        if nak_seq is not None and nak_seq == self._seq:
            if reason == "syntax" and not self.done.is_set():
                self.error = WcdriveProtocolError(
                    f"{self.name} refused {HELLO_COMMAND.decode()} (NAK {reason}): its firmware "
                    f"speaks protocol v3 or older, whose lines carry no CRC; this wcdrive speaks "
                    f"v{PROTOCOL_VERSION}. Flash the firmware that comes with it (wcdrive bench "
                    "flash)")
                self.done.set()
                return
            self._rejected = True
        if self._rejected:
            self.step(now)

    def garbled(self, now: float) -> None:
        """The board refused a line (``ERR:``): during the handshake, a garbled hello,
        so the next goes out as soon as it may."""
        if not self.done.is_set() and self._tries:
            self._rejected = True
            self.step(now)

    def forget(self) -> None:
        """The board has reset: the handshake starts over. Under ``lock`` when the
        reader and the monitor both run."""
        self.protocol_version = 0
        self.error = None
        self.done.clear()
        self._tries = 0
        self._seq = -1
