"""The runtime parameters of protocol v2 (``get:<name>`` / ``set:<name>=<value>``), the
sketch's ``PARAM_NAMES``/``PARAM_VARS``/``PARAM_MIN``/``PARAM_MAX``: the spec's table
(``wcdrive.protocol.spec.PARAMETERS``) with its ranges rounded to binary32 as the
firmware holds them."""

from __future__ import annotations

from dataclasses import dataclass

from wcdrive.avr.f32 import f32
from wcdrive.protocol.spec import PARAMETERS, PROFILE_PARAMETERS, PROFILES


@dataclass(frozen=True)
class Param:
    """One row of the firmware's parameter table."""

    name: str          # as on the wire
    field: str         # FirmwareState field (the firmware global of the same name)
    low: float | int
    high: float | int
    integer: bool = False


PARAMS: tuple[Param, ...] = tuple(
    Param(p.name, p.field, int(p.low) if p.integer else f32(p.low),
          int(p.high) if p.integer else f32(p.high), p.integer)
    for p in PARAMETERS)
BY_NAME: dict[bytes, int] = {p.name.encode(): i for i, p in enumerate(PARAMS)}
#: The drive limits a profile's row holds, and the table index of the first
#: (``PARAM_DRIVE_FIRST``): ``wcdrive.firmware.profiles``.
PROFILE_FLOATS = len(PROFILE_PARAMETERS)
DRIVE_FIRST = next(i for i, p in enumerate(PARAMS) if p.name == PROFILE_PARAMETERS[0])
assert tuple(p.name for p in PARAMS[DRIVE_FIRST:DRIVE_FIRST + PROFILE_FLOATS]) == PROFILE_PARAMETERS
#: ``PROFILE_PRESETS``: the profiles' presets, row after row, as binary32.
PRESETS: tuple[float, ...] = tuple(f32(v) for profile in PROFILES for v in profile.values)
