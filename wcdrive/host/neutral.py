"""Neutral before motion, on the host: the board drives only once a neutral (zero)
command has stood ``NEUTRAL_TICKS`` control ticks, after a boot, an e-stop or fault
reset, a watchdog stop and a PPM loss (docs/safety.md, "Neutral before motion").

``wait_for_neutral`` sends stops until the board's ``TLM:`` line says it no longer
waits (its state bit 0; on CAN, WC_STATUS_E's), or, for a board whose telemetry
carries no state (protocol v1, a 13-field TLM line), until the board surely confirmed one. ``connect`` and
``reset_estop`` call it: opening a chair and releasing its e-stop are a program's own
decisions. After a watchdog stop or a board reset mid-run they are not: motion raises
``WcdriveNeutralError`` until the program sends a stop itself, so that a program that
keeps sending its last command across a lost link does not move the chair.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from wcdrive.errors import WcdriveInhibitError, WcdriveNeutralError, WcdriveTimeoutError
from wcdrive.host.board_state import BoardState
from wcdrive.protocol.motion import VelocityCommand, find_motion
from wcdrive.protocol.spec import integer

__all__ = ["CONFIRM_S", "is_neutral", "refuse_unready_motion", "wait_for_neutral"]

#: The board's ticks after a stop by which it surely confirmed it: NEUTRAL_TICKS and
#: the tick it arrived in, with a tick to spare for the line that says so.
CONFIRM_TICKS = integer("NEUTRAL_TICKS") + 2
#: The same in seconds, for a board that sends no TLM line to count.
CONFIRM_S = CONFIRM_TICKS * integer("CONTROL_PERIOD_MS") / 1000.0
#: How often a stop goes out again while the host waits.
_RESEND_S = 0.1


def is_neutral(command: bytes) -> bool:
    """Whether ``command`` is a neutral one (a motion command of zeros): it goes out while
    the board waits for neutral; any other motion raises."""
    motion = find_motion(command)
    if motion is None:
        return False
    values = (motion.linear, motion.angular) if isinstance(motion, VelocityCommand) else (motion.left,
                                                                                          motion.right)
    return all(v == 0.0 for v in values)


def refuse_unready_motion(board: BoardState, command: bytes, name: str, current: bool) -> None:
    """Raises for a motion ``command`` the board would refuse for neutral or an inhibit
    (``current``: it speaks this protocol version, whose TLM says both): an engaged
    inhibit input that stops the chair (``WcdriveInhibitError``), a wait for neutral
    (``WcdriveNeutralError``). A neutral command always goes out."""
    if not current or is_neutral(command):
        return
    status = board.status
    if status is not None and status.push_mode:
        raise WcdriveInhibitError(f"{name} has its brake released by hand (push mode) and refuses "
                                  "motion until the lever is back")
    if status is not None and status.drive_inhibited:
        raise WcdriveInhibitError(f"{name} has an inhibit input engaged (the charger?) and refuses "
                                  "motion until it is released (a latching one: then reset_estop())")
    if board.awaiting_neutral:
        raise WcdriveNeutralError(f"{name} drives only after a neutral command (after a watchdog stop, "
                                  "a reset, a PPM loss or an inhibit): stop() or wait_for_neutral() first")


def wait_for_neutral(board: BoardState, stop: Callable[[], None], timeout: float, name: str, *,
                     telemetry: bool = True) -> None:
    """Sends ``stop`` until a ``TLM:`` line that ``board`` read after it shows the board
    drives again (at most ``timeout`` s: ``WcdriveTimeoutError``). A board whose
    telemetry carries no state (its TLM line ends before it, or ``telemetry`` False: no
    TLM at all, protocol v1): one stop and ``CONFIRM_S``."""
    deadline = time.monotonic() + timeout
    stop()
    sent, seen = time.monotonic(), board.telemetry_count
    if not telemetry:
        time.sleep(CONFIRM_S)
        return
    while board.telemetry_count == seen or board.awaiting_neutral:
        status = board.status
        if board.telemetry_count != seen and status is not None and status.state is None:
            # the board says nothing of it (a 13-field TLM line): its own ticks, counted
            while board.telemetry_count < seen + CONFIRM_TICKS and time.monotonic() < deadline:
                time.sleep(0.01)
            board.awaiting_neutral = False
            return
        now = time.monotonic()
        if now > deadline:
            raise WcdriveTimeoutError(f"{name} did not confirm a neutral command within {timeout:g} s "
                                      "(its telemetry still says it waits for one)")
        if now - sent >= _RESEND_S:
            stop()
            sent = now
        time.sleep(0.01)
