"""wcdrive's exceptions: one root, messages that say what to do."""

from __future__ import annotations


class WcdriveError(Exception):
    """Root of every wcdrive error."""


class WcdriveConnectionError(WcdriveError):
    """The board could not be reached, or the link was lost."""


class WcdrivePermissionError(WcdriveConnectionError, PermissionError):
    """The serial device exists but this user may not open it."""


class WcdriveTimeoutError(WcdriveError, TimeoutError):
    """The board did not answer in time."""
