"""What the command line shows a person: progress bars (``rich``), the one-line error
report, and the exit status of each kind of failure.

Progress is drawn on stderr only when stderr is a terminal and the command was not
asked for ``--json``; otherwise every call is a no-op, so output for machines stays
clean.
"""

from __future__ import annotations

import logging
import sys
from types import TracebackType
from typing import Any

import serial

from wcdrive._util.native import BuildError
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)

#: Exit statuses, one per kind of failure (``wcdrive --help`` lists them).
OK = 0
CHECK_FAILED = 1          # the command ran and what it checked failed (differences, failed runs)
USAGE = 2                 # bad arguments, scenario or spec file
CONNECTION = 3            # the chair, device or cluster could not be reached or was lost
TIMEOUT = 4               # the board did not answer in time
PROTOCOL = 5              # the board spoke another protocol or version
COMMAND = 6               # the board refused a command (e-stop latched, fault, out of range)
BUILD = 7                 # the firmware or a C helper could not be built (toolchain missing)
INTERNAL = 70             # a bug: an unexpected exception (--debug shows the traceback)
INTERRUPTED = 130         # Ctrl-C (128 + SIGINT)

EXIT_CODES = {"ok": OK, "check failed": CHECK_FAILED, "usage": USAGE, "connection": CONNECTION,
              "timeout": TIMEOUT, "protocol": PROTOCOL, "command refused": COMMAND, "build": BUILD,
              "internal error": INTERNAL, "interrupted": INTERRUPTED}


def exit_code(exc: BaseException) -> int:
    """The exit status for an exception that ended a command."""
    if isinstance(exc, KeyboardInterrupt):
        return INTERRUPTED
    if isinstance(exc, WcdriveTimeoutError):
        return TIMEOUT
    if isinstance(exc, WcdriveConnectionError):
        return CONNECTION
    if isinstance(exc, WcdriveProtocolError):
        return PROTOCOL
    if isinstance(exc, WcdriveCommandError):
        return COMMAND
    if isinstance(exc, BuildError):
        return BUILD
    if isinstance(exc, serial.SerialException | ConnectionError | TimeoutError):
        return CONNECTION
    if isinstance(exc, RuntimeError):       # HarnessError too (the virtual board broke): a bug
        return INTERNAL
    if isinstance(exc, WcdriveError | ValueError | FileNotFoundError):
        return USAGE
    return INTERNAL


def error_line(command: str, exc: BaseException) -> str:
    """The one line printed for ``exc``: the command, then the error's first line."""
    if isinstance(exc, KeyboardInterrupt):
        return f"wcdrive {command}: interrupted"
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if exit_code(exc) == INTERNAL:
        text = f"internal error ({type(exc).__name__}: {text}); run with --debug for the traceback"
    return f"wcdrive {command}: {text}"


def setup_logging(debug: bool) -> None:
    """The ``wcdrive`` loggers to stderr: warnings and up, everything with --debug."""
    logger = logging.getLogger("wcdrive")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(name)s: %(levelname)s: %(message)s"))
        logger.addHandler(handler)
    logger.setLevel(logging.DEBUG if debug else logging.WARNING)


def progress_enabled(json_output: bool = False) -> bool:
    """Whether to draw progress: stderr is a terminal and no --json."""
    return sys.stderr.isatty() and not json_output


class Bar:
    """A ``rich`` progress bar on stderr over ``total`` steps (or a fraction, with
    ``total=1.0``); does nothing when not ``enabled``. A context manager."""

    def __init__(self, label: str, total: float, enabled: bool) -> None:
        self.label, self.total, self.enabled = label, total, enabled
        self._progress: Any = None
        self._task: Any = None

    def __enter__(self) -> Bar:
        if self.enabled:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

            columns = [*Progress.get_default_columns()[:1], BarColumn(),
                       MofNCompleteColumn() if self.total > 1 else Progress.get_default_columns()[2],
                       TimeRemainingColumn()]
            self._progress = Progress(*columns, console=Console(stderr=True), transient=True)
            self._progress.start()
            self._task = self._progress.add_task(self.label, total=self.total)
        return self

    def advance(self, steps: float = 1.0) -> None:
        """``steps`` more done."""
        if self._progress is not None:
            self._progress.advance(self._task, steps)

    def update(self, completed: float) -> None:
        """``completed`` done in all (a fraction for ``total=1.0``)."""
        if self._progress is not None:
            self._progress.update(self._task, completed=completed)

    def __call__(self, fraction: float) -> None:
        self.update(fraction * self.total)

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
