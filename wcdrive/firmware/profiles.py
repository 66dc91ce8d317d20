"""The drive profiles as final_control.ino keeps them: ``profileTable``,
``presetProfiles`` and ``useProfile`` (docs/safety.md, "Drive profiles").

``PROFILE_COUNT`` rows of the seven drive limits (``PROFILE_PARAMETERS``, in the
parameter table's order; ``wcdrive.firmware.drive`` applies them). One row is in force,
the runtime parameter ``profile``: its values are the drive limits' globals, and
``set:`` of a drive limit changes the global and the row together, so the table always
holds what a profile selected again gives. ``set:profile=<n>`` puts row n in force;
``save`` stores every row and the number; ``defaults`` puts the presets (the spec's
``[[profile]]``) back, and profile ``PROFILE`` in force. The table lives in the port's
state flat, row after row (``FirmwareState.profileTable``).
"""

from __future__ import annotations

from wcdrive.firmware.params import DRIVE_FIRST, PARAMS, PRESETS, PROFILE_FLOATS
from wcdrive.firmware.state import FirmwareState

__all__ = ["drive_limit_set", "preset_profiles", "use_profile"]

_FIELDS = tuple(p.field for p in PARAMS[DRIVE_FIRST:DRIVE_FIRST + PROFILE_FLOATS])


def preset_profiles(s: FirmwareState) -> None:
    """``presetProfiles``: the table back to its presets."""
    s.profileTable[:] = PRESETS


def use_profile(s: FirmwareState, number: int) -> None:
    """``useProfile``: profile ``number`` in force, its row the drive limits."""
    s.profile = number
    row = s.profileTable[number * PROFILE_FLOATS:(number + 1) * PROFILE_FLOATS]
    for field, value in zip(_FIELDS, row, strict=True):
        setattr(s, field, value)


def drive_limit_set(s: FirmwareState, index: int, value: float) -> None:
    """After ``set:`` of parameter ``index``: a drive limit's row entry follows it."""
    if DRIVE_FIRST <= index < DRIVE_FIRST + PROFILE_FLOATS:
        s.profileTable[s.profile * PROFILE_FLOATS + index - DRIVE_FIRST] = value
