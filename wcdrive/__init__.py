"""wcdrive: firmware-in-the-loop hardware abstraction for a Mega-2560 power wheelchair."""

import serial as _serial

if "wcdrive.urlhandler" not in _serial.protocol_handler_packages:
    _serial.protocol_handler_packages.append("wcdrive.urlhandler")

__version__ = "0.1.0"

from wcdrive.api import Telemetry, Wheelchair, connect
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveError,
    WcdriveEstopError,
    WcdrivePermissionError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)

__all__ = ["Telemetry", "WcdriveCommandError", "WcdriveConnectionError", "WcdriveError",
           "WcdriveEstopError", "WcdrivePermissionError", "WcdriveProtocolError",
           "WcdriveTimeoutError", "Wheelchair", "connect"]
