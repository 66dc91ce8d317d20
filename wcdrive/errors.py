"""wcdrive's exceptions: one root, messages that say what to do.

Everything wcdrive raises derives from ``WcdriveError``, so ``except WcdriveError``
catches it all; each error also keeps the built-in base it had before, so an older
``except ValueError`` or ``except RuntimeError`` still catches it.

- The board and the link (this module): ``WcdriveConnectionError`` (with
  ``WcdrivePermissionError``, also a ``PermissionError``, and ``WcdriveBusyError``),
  ``WcdriveTimeoutError`` (also a ``TimeoutError``), ``WcdriveProtocolError`` and
  ``WcdriveCommandError`` (with ``WcdriveEstopError`` and its ``WcdriveFaultError``,
  and ``WcdriveNeutralError``).
- A file or a configuration wcdrive cannot use: ``WcdriveFileError``, also a
  ``ValueError``. Its subclasses live beside what they read: ``ChairFileError``
  (``wcdrive.plant.params``), ``WorldError`` (``wcdrive.plant.world``), ``MapFileError``
  (``wcdrive.plant.rosmap``), ``ScenarioError`` (``wcdrive.sim.scenario``), ``SpecError``
  (``wcdrive.tools.sweep``), ``RecordingError`` (``wcdrive.tools.identify``),
  ``ReplayError`` (``wcdrive.tools.replay``) and ``HexError``
  (``wcdrive.boards.simavr.bootloader_mega``).
- The others, also beside their modules: ``CanCodecError`` (also a ``ValueError``: a
  line or CAN frame with no counterpart, ``wcdrive.protocol.can_frames``), ``BuildError``
  (also a ``RuntimeError``: a C helper, the simavr harness or the firmware could not be
  built, ``wcdrive._util.native``), ``HarnessError`` (also a ``RuntimeError``: the
  virtual board could not be made or stopped, ``wcdrive.boards.simavr.virtual_mega``),
  ``FlashError`` (``wcdrive.tools.bench``) and the firmware ports' ``ParseError``
  (``wcdrive.firmware.commands``, ``wcdrive.eddie.firmware``), which the ports catch
  themselves to answer a malformed command.

One exception stays outside on purpose: ``wcdrive.tools.bench.Interrupted`` (Ctrl-C
during ``bench run``, carrying the recording so far) is a ``KeyboardInterrupt``, so that
no ``except Exception`` swallows Ctrl-C. ``wcdrive.protocol.codec.Error`` is no exception
at all: it is the parsed ``ERR:`` line of the protocol. tests/meta/test_errors.py holds
all this.
"""

from __future__ import annotations


class WcdriveError(Exception):
    """Root of every wcdrive error."""


class WcdriveFileError(WcdriveError, ValueError):
    """A file or a configuration that wcdrive cannot use (a chair file, a world, a map, a
    scenario, a sweep spec, a recording, an Intel HEX file, ...); the message names the
    file and the entry. Also a ``ValueError``, as these errors always were."""


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


class WcdriveNeutralError(WcdriveCommandError):
    """Motion refused: the board drives only after a neutral (zero) command, after a
    boot, a reset, a watchdog stop or a PPM loss. Call ``stop()`` (or
    ``wait_for_neutral()``) once the command it held should no longer drive the chair."""

    def __init__(self, message: str) -> None:
        super().__init__(message, "neutral")


class WcdriveInhibitError(WcdriveCommandError):
    """Motion refused: an inhibit input of the board is engaged (the charger plugged in,
    say; ``chair.inhibited``). It ends when the input is released (a latching one, after
    ``reset_estop()`` too); then the board wants a neutral command first."""

    def __init__(self, message: str) -> None:
        super().__init__(message, "inhibit")
