"""wcdrive: firmware-in-the-loop hardware abstraction for a Mega-2560 power wheelchair."""

import logging as _logging

import serial as _serial

if "wcdrive.transports.urlhandler" not in _serial.protocol_handler_packages:
    _serial.protocol_handler_packages.append("wcdrive.transports.urlhandler")

__version__ = "0.1.0"

from wcdrive.api import LinkEvent, LinkLost, LinkRestored, Reset, Telemetry, Wheelchair, connect
from wcdrive.errors import (
    WcdriveBusyError,
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveError,
    WcdriveEstopError,
    WcdriveFaultError,
    WcdriveInhibitError,
    WcdriveNeutralError,
    WcdrivePermissionError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)
from wcdrive.host.robot import Robot
from wcdrive.host.wheelchair import stop_all

__all__ = [
    "EddieRobot",
    "LinkEvent",
    "LinkLost",
    "LinkRestored",
    "Reset",
    "Robot",
    "Telemetry",
    "WcdriveBusyError",
    "WcdriveCommandError",
    "WcdriveConnectionError",
    "WcdriveError",
    "WcdriveEstopError",
    "WcdriveFaultError",
    "WcdriveInhibitError",
    "WcdriveNeutralError",
    "WcdrivePermissionError",
    "WcdriveProtocolError",
    "WcdriveTimeoutError",
    "Wheelchair",
    "connect",
    "stop_all",
]

# The library logs under the "wcdrive" hierarchy (wcdrive.session: connections, resets,
# faults, NAKs, dropped lines; wcdrive.telemetry; wcdrive.sweep) and leaves output to
# the application: nothing is printed unless it configures logging.
_logging.getLogger("wcdrive").addHandler(_logging.NullHandler())


def __getattr__(name: str) -> object:
    """``wcdrive.EddieRobot``: the Eddie plugin's robot class, found through the robot
    registry (``wcdrive.host.robots``) when first asked for."""
    if name == "EddieRobot":
        from wcdrive.host.robots import registered

        robot_class: object = registered()["eddie"].extras["robot_class"]
        return robot_class
    raise AttributeError(f"module 'wcdrive' has no attribute {name!r}")
