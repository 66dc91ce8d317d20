"""The host's motion commands, without I/O: one wheel order, one validation, one
encoding and one parser, for every host (``Wheelchair``, ``SteppedChair``, the scenario
runner, the ROS 2 recorder and the CAN gateway).

    velocity_command(0.5, 0.1)     -> b"x:0.500,t:0.100,"
    wheel_command(left=3.0, right=5.0) -> b"rp5.000,lp3.000,"   (the wire puts right first)
    parse_motion(b"rp5.000,lp3.000,")  -> WheelCommand(left=3.0, right=5.0)

The public order is (left, right), as ROS's ``left_wheel_names``/``right_wheel_names``
and ``Wheelchair.set_wheels`` have it; only the wire text (the seed's format) puts the
right wheel first. A value outside its range (or not finite) is a ``ValueError``;
one inside is sent as the board will read it (``as_board_reads``): the board takes
every command it is sent, so a velocity at the exact limit drives through every host
alike.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.f32 import f32
from wcdrive.protocol.codec import MAX_ANGULAR, MAX_LINEAR, MAX_WHEEL, encode_cmdvel, encode_wheel

__all__ = ["VelocityCommand", "WheelCommand", "as_board_reads", "find_motion", "parse_motion",
           "velocity_command", "wheel_command"]

# The one grammar of a motion command's body (unframed): the board's fields, an
# optional sign on a velocity, the last comma optional.
_CMDVEL = rb"x:([-+]?[\d.]+),t:([-+]?[\d.]+),?"
_WHEEL = rb"r([pn])([\d.]+),l([pn])([\d.]+),?"
_MOTION = re.compile(rb"(?:" + _CMDVEL + rb")|(?:" + _WHEEL + rb")")


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """``x:<m/s>,t:<rad/s>,``: the chair's linear and angular velocity."""

    linear: float
    angular: float


@dataclass(frozen=True, slots=True)
class WheelCommand:
    """``r<p|n><rad/s>,l<p|n><rad/s>,``: each wheel's speed, forward positive."""

    left: float
    right: float


def as_board_reads(value: float, limit: float) -> float:
    """``value`` (already checked against ``limit``) at the 3 decimals the codec writes,
    stepped 0.001 toward zero when the board would read that text just past its
    binary32 limit: avr-libc's ``strtod`` is not correctly rounded, and reads "9.400"
    as 9.4000006, above the firmware's 9.3999996, so ``x:0.000,t:9.400,`` is refused."""
    text = f"{abs(value):.3f}"
    while strtod(text.encode())[0] > f32(limit):
        text = f"{float(text) - 0.001:.3f}"
    return math.copysign(float(text), value)


def velocity_command(linear: float, angular: float) -> bytes:
    """The CMDVEL body for ``linear`` m/s and ``angular`` rad/s (ValueError when out of
    range or not finite)."""
    encode_cmdvel(linear, angular)             # ValueError when out of range
    return encode_cmdvel(as_board_reads(linear, MAX_LINEAR), as_board_reads(angular, MAX_ANGULAR))


def wheel_command(left: float, right: float) -> bytes:
    """The WHEEL body for the wheel speeds ``left`` and ``right`` in rad/s (ValueError
    when out of range or not finite)."""
    encode_wheel(right, left)                  # ValueError when out of range
    return encode_wheel(as_board_reads(right, MAX_WHEEL), as_board_reads(left, MAX_WHEEL))


def _command(m: re.Match[bytes]) -> VelocityCommand | WheelCommand:
    if m[1] is not None:
        return VelocityCommand(float(m[1]), float(m[2]))
    right = float(m[4]) * (-1.0 if m[3] == b"n" else 1.0)
    left = float(m[6]) * (-1.0 if m[5] == b"n" else 1.0)
    return WheelCommand(left=left, right=right)


def parse_motion(body: bytes) -> VelocityCommand | WheelCommand | None:
    """The motion command that ``body`` (a whole unframed command) is, or None for any
    other command. A number that is not one (``1.2.3``) is a ``ValueError``."""
    m = _MOTION.fullmatch(body)
    return None if m is None else _command(m)


def find_motion(data: bytes) -> VelocityCommand | WheelCommand | None:
    """The first motion command within ``data`` (bytes a host wrote: framed or not, a
    line or several), or None."""
    m = _MOTION.search(data)
    return None if m is None else _command(m)
