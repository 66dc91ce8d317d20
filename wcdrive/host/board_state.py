"""What the host knows of the board and holds of it: its latest ``TLM:`` line, the
e-stop and faults it announced, why it last reset, what it loaded its parameters from,
and the e-stop the host holds latched on it.

``BoardState`` is written by the reader thread (``note_telemetry``, ``note_event``,
``note_boot``) and by ``Wheelchair`` (``estop_held``, ``estop_released``); the session
calls ``forget`` when the board resets. Every field is one assignment, read without a
lock.

Why the host holds the e-stop: a board that resets (a brown-out, a reopened device)
boots without it, and an e-stop sent while the link was down may never have arrived.
``estop_lost`` tells the session when to latch it again.
"""

from __future__ import annotations

import logging

from wcdrive._util.history import History
from wcdrive.protocol.codec import Boot, Event, ExtendedTelemetry

__all__ = ["BoardState"]

_log = logging.getLogger("wcdrive.session")


class BoardState:
    """The state of the board named ``name`` (for the log), as its lines report it."""

    def __init__(self, name: str) -> None:
        self.name = name
        #: The latest TLM line (after hello), or None.
        self.status: ExtendedTelemetry | None = None
        #: Set when the board announced an e-stop (``EVT:ESTOP``); cleared by a reset
        #: and when the link is reopened onto a board that has reset.
        self.estop_announced = False
        #: The host holds the e-stop latched (``Wheelchair.estop`` until ``reset_estop``):
        #: a board that reset meanwhile (a reconnect) gets ``estop`` right after hello.
        self.estop_held = False
        #: Faults the board announced (``EVT:FAULT,<name>``) since the last reset.
        self.faults_announced: History[str] = History()
        #: The cause of the board's last reset as its ``BOOT:`` line gave it ("" before one).
        self.reset_cause = ""
        #: What the board said of its parameters at its last boot: ``PARAMS_LOADED`` or
        #: ``PARAMS_DEFAULT,<why>`` ("" before such a line; a board without parameters in EEPROM sends none).
        self.params_at_boot = ""
        self._check_estop = False               # the next TLM decides whether to re-latch
        #: The board waits for a neutral command before it drives (``wcdrive.host.neutral``):
        #: as its TLM lines say, and from its boot, an e-stop reset, ``EVT:WATCHDOG``,
        #: ``EVT:PPM_LOST`` or ``EVT:NOT_NEUTRAL`` until the next TLM line says.
        self.awaiting_neutral = True
        #: TLM lines read so far.
        self.telemetry_count = 0

    @property
    def faults(self) -> tuple[str, ...]:
        """The faults the board has latched: those of its latest TLM line, then those it
        announced that the line does not name."""
        status = self.status
        names = list(status.fault_names) if status is not None else []
        for name in self.faults_announced:
            if name not in names:
                names.append(name)
        return tuple(names)

    @property
    def estop_latched(self) -> bool:
        """True while the e-stop is latched: as the board reports it, or as the host
        holds it or the board announced it."""
        status = self.status
        if status is not None and status.estop_latched:
            return True
        return self.estop_held or self.estop_announced

    def note_telemetry(self, msg: ExtendedTelemetry) -> None:
        """The board's latest TLM line."""
        self.status = msg
        self.telemetry_count += 1
        self.awaiting_neutral = msg.needs_neutral     # a board without the state never waits

    def note_boot(self, msg: Boot) -> None:
        """The board's ``BOOT:`` line."""
        self.reset_cause = msg.cause

    def note_event(self, msg: Event) -> None:
        """An ``EVT:`` line: parameters loaded, the e-stop or a fault latched, or another
        event (logged)."""
        if msg.name.startswith("PARAMS_"):
            self.params_at_boot = msg.name
        if msg.name == "ESTOP":
            _log.warning("%s: e-stop latched on the board", self.name)
            self.estop_announced = True
        elif msg.fault is not None:
            _log.error("%s: the board latched a fault: %s", self.name, msg.fault)
            self.faults_announced.append(msg.fault)
        elif msg.name in ("WATCHDOG", "PPM_LOST", "NOT_NEUTRAL", "INHIBIT,1,0", "INHIBIT,2,0", "PUSH,0"):
            _log.warning("%s: %s: the board may need a neutral command before it drives again", self.name,
                         msg.name)
            self.awaiting_neutral = True
        else:
            _log.info("%s: board event %s", self.name, msg.name)

    def check_estop_at_next_telemetry(self) -> None:
        """The link came back: if the host holds the e-stop, the next TLM line says
        whether the board has it (one sent while the link was down may not)."""
        if self.estop_held:
            self._check_estop = True

    def estop_lost(self, msg: ExtendedTelemetry) -> bool:
        """Whether the TLM line ``msg``, the one a restored link waits for, shows that
        the board lacks the e-stop the host holds (it must be latched again)."""
        if not self._check_estop:
            return False
        self._check_estop = False
        return self.estop_held and not msg.estop_latched

    def estop_released(self) -> None:
        """The board took ``reset``: no e-stop or fault is latched, and the last TLM line
        predates the reset."""
        self.estop_held = False
        self.estop_announced = False
        self.faults_announced.clear()
        self.status = None

    def forget(self) -> None:
        """The board has reset: what it reported is gone (an e-stop the host holds is
        latched again after hello)."""
        self.status = None
        self.estop_announced = False
        self.faults_announced.clear()           # a board that reset has no fault latched
        self._check_estop = False
        self.awaiting_neutral = True
