"""wcdrive's exceptions: one root, messages that say what to do."""

from __future__ import annotations


class WcdriveError(Exception):
    """Root of every wcdrive error."""


class WcdriveConnectionError(WcdriveError):
    """The board could not be reached, or the link was lost."""


class WcdrivePermissionError(WcdriveConnectionError, PermissionError):
    """The serial device exists but this user may not open it."""


class WcdriveBusyError(WcdriveConnectionError):
    """The serial device is open in another program (wcdrive opens it exclusively)."""


class WcdriveTimeoutError(WcdriveError, TimeoutError):
    """The board did not answer in time."""


class WcdriveProtocolError(WcdriveError):
    """The board does not speak this host's protocol (no answer to hello, an unknown
    version), or not what was asked (a legacy v1 board and estop())."""


class WcdriveCommandError(WcdriveError):
    """The board refused a command (a NAK); ``reason`` is its word for why."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class WcdriveEstopError(WcdriveCommandError):
    """Motion refused: the e-stop is latched. Call ``reset_estop()`` once it is safe."""


class WcdriveFaultError(WcdriveEstopError):
    """The board has latched a fault (an encoder or the motor driver, ``EVT:FAULT``) and
    refuses motion until ``reset_estop()``; ``faults`` names them."""

    def __init__(self, message: str, faults: tuple[str, ...]) -> None:
        super().__init__(message, "fault")
        self.faults = faults
