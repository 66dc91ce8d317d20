"""Parameters in EEPROM: ``saveParams``, ``restoreDefaults``, ``loadParams`` and the
EEPROM-ready interrupt (``eepromReady``) of final_control.ino.

The EEPROM is ``FirmwareState.eeprom`` (``EEPROM_SIZE`` bytes, erased to 0xFF). The
parameter block at ``EEPROM_PARAMS_ADDR`` (protocol/PROTOCOL.md, "Parameters in
EEPROM"): the layout version, the 10 float parameters before the drive limits in table
order (binary32, little-endian), the drive profiles' table (``PROFILE_COUNT`` rows of
the 8 drive limits, ``wcdrive.firmware.profiles``), ``watchdog_ms`` (uint16),
``feedback_form``, ``brake_fitted`` and ``profile`` (uint8 each), and the
CRC-16/XMODEM of those 174 bytes (uint16, little-endian), 176 bytes in all.

``save`` snapshots the block into ``eeBlock`` and writes its first byte that differs
from the EEPROM; each EEPROM-ready interrupt (3.4 ms later on the chip) writes the next
one (``eeprom_ready``), until every byte matches. Which interrupts come, and when, is a
matter of the chip's timing: the lock-step harness gives each to the port as an event.
"""

from __future__ import annotations

import binascii
import struct

from wcdrive.firmware import constants as C
from wcdrive.firmware.output import CRLF, send, send_event
from wcdrive.firmware.params import DRIVE_FIRST, PARAMS, PRESETS, PROFILE_FLOATS
from wcdrive.firmware.profiles import drive_limit_set, preset_profiles, use_profile
from wcdrive.firmware.state import EE_BLOCK_BYTES, FirmwareState

#: The block's bytes before its CRC, and in all.
BLOCK_BYTES = EE_BLOCK_BYTES
DATA_BYTES = BLOCK_BYTES - 2
#: The float parameters before the drive limits, and the parameter each of the block's
#: floats is checked against: those, then the table's, row by row.
_FLOATS = PARAMS[:DRIVE_FIRST]
_BLOCK_FLOATS = _FLOATS + PARAMS[DRIVE_FIRST:DRIVE_FIRST + PROFILE_FLOATS] * (len(PRESETS) // PROFILE_FLOATS)
_WATCHDOG = next(p for p in PARAMS if p.field == "watchdogMs")
_FORM = next(p for p in PARAMS if p.field == "feedbackForm")
_FITTED = next(p for p in PARAMS if p.field == "brakeFitted")
_PROFILE = next(p for p in PARAMS if p.field == "profile")
#: Where the table, ``watchdog_ms``, ``feedback_form``, ``brake_fitted`` and ``profile``
#: sit in the block.
_TABLE_AT = 1 + 4 * len(_FLOATS)
_WATCHDOG_AT = 1 + 4 * len(_BLOCK_FLOATS)
_FORM_AT = _WATCHDOG_AT + 2
_FITTED_AT = _FORM_AT + 1
_PROFILE_AT = _FITTED_AT + 1
#: A parameter's place in the table, by field.
_INDEX = {p.field: i for i, p in enumerate(PARAMS)}
#: The parameters' defaults (the globals' initial values).
_DEFAULT_VALUES: dict[str, float | int] = {p.field: getattr(FirmwareState(), p.field) for p in PARAMS}


def ee_crc(block: bytes | bytearray) -> int:
    """``eeCrc``: CRC-16/XMODEM of the block's data bytes."""
    return binascii.crc_hqx(bytes(block[:DATA_BYTES]), 0)


def pack(s: FirmwareState) -> bytes:
    """The block that ``save`` writes for the parameters in force."""
    data = bytes([C.EEPROM_LAYOUT]) + b"".join(struct.pack("<f", getattr(s, p.field)) for p in _FLOATS)
    data += struct.pack(f"<{len(s.profileTable)}f", *s.profileTable)
    data += struct.pack("<HBBB", getattr(s, _WATCHDOG.field), getattr(s, _FORM.field),
                        getattr(s, _FITTED.field), s.profile)
    return data + struct.pack("<H", ee_crc(data))


def block_image(values: dict[str, float | int] | None = None, *, layout: int = C.EEPROM_LAYOUT) -> bytes:
    """An EEPROM image (``EEPROM_SIZE`` bytes, erased elsewhere) holding a block with the
    defaults overridden by ``values`` (FirmwareState field names), as ``save`` writes it;
    ``layout`` other than ``EEPROM_LAYOUT`` makes a block of another layout version. A
    drive limit given sets it in the row of the profile in force (``profile``, given or
    the default)."""
    s = FirmwareState()
    values = values or {}
    if "profile" in values:
        use_profile(s, int(values["profile"]))
    for name, value in values.items():
        setattr(s, name, value)
        if name in _INDEX:
            drive_limit_set(s, _INDEX[name], float(value))
    block = bytearray(pack(s))
    if layout != C.EEPROM_LAYOUT:
        block[0] = layout
        block[DATA_BYTES:] = struct.pack("<H", ee_crc(block))
    image = bytearray(b"\xff" * C.EEPROM_SIZE)
    image[C.EEPROM_PARAMS_ADDR:C.EEPROM_PARAMS_ADDR + BLOCK_BYTES] = block
    return bytes(image)


def image_for(event: str) -> bytes:
    """An EEPROM image with which ``setup()`` sends ``event`` (``PARAMS_LOADED``: the
    defaults saved; ``PARAMS_DEFAULT,<why>``: a block that fails that way): for a replay,
    which sees the board's event but not its EEPROM."""
    if event == "PARAMS_LOADED":
        return block_image()
    why = event.removeprefix("PARAMS_DEFAULT,")
    if why == "blank":
        return b"\xff" * C.EEPROM_SIZE
    if why == "version":
        return block_image(layout=C.EEPROM_LAYOUT + 1)
    image = bytearray(block_image())
    if why == "crc":
        image[C.EEPROM_PARAMS_ADDR + DATA_BYTES] ^= 0xFF
    elif why == "range":
        image = bytearray(block_image({_WATCHDOG.field: 0}))
    else:
        raise ValueError(f"no EEPROM gives {event!r}")
    return bytes(image)


def ee_write_next(s: FirmwareState) -> None:
    """``eeWriteNext``: writes the next byte of ``eeBlock`` that differs from the EEPROM
    (the interrupt then comes back), or, when none does, turns the interrupt off."""
    base = C.EEPROM_PARAMS_ADDR
    while s.eeNext < BLOCK_BYTES and s.eeprom[base + s.eeNext] == s.eeBlock[s.eeNext]:
        s.eeNext += 1
    if s.eeNext == BLOCK_BYTES:
        s.eeBusy = 0
        return
    s.eeprom[base + s.eeNext] = s.eeBlock[s.eeNext]
    s.eeNext += 1
    s.eeBusy = 1


def eeprom_ready(s: FirmwareState) -> None:
    """``eepromReady``: the EEPROM-ready interrupt (the last write is done)."""
    ee_write_next(s)


def writing(s: FirmwareState) -> bool:
    """Whether a save is still being written (``eeBusy``: the EEPROM-ready interrupt is
    on, until it finds every byte written and the last write done)."""
    return bool(s.eeBusy)


#: An EEPROM byte's write time, in cycles at 16 MHz: 3.4 ms, as simavr times it (the
#: datasheet gives 3.3 ms).
WRITE_CYCLES = 54_400


class ReadyInterrupt:
    """The EEPROM-ready interrupt in time, for a board that runs the port against a
    clock (``PortLoop``): ``poll(state, cycle)`` calls ``eeprom_ready`` once
    ``WRITE_CYCLES`` have passed since the write it first saw in progress (at most one
    interrupt a poll's worth of time late)."""

    def __init__(self) -> None:
        self.due: int | None = None

    def poll(self, s: FirmwareState, cycle: int) -> None:
        """At ``cycle``: the interrupts that are due."""
        while s.eeBusy:
            if self.due is None:
                self.due = cycle + WRITE_CYCLES
            if cycle < self.due:
                return
            eeprom_ready(s)
            self.due += WRITE_CYCLES
        self.due = None


def save_params(s: FirmwareState) -> str | None:
    """``saveParams``: ``save``; ``busy`` while the last save is being written."""
    if writing(s):
        return "busy"
    s.eeBlock[:] = pack(s)
    s.eeNext = 0
    ee_write_next(s)
    return None


def restore_defaults(s: FirmwareState) -> None:
    """``restoreDefaults``: ``defaults`` (the EEPROM is not written): every parameter but
    ``brake_fitted``, which says what the chair has, not how it is tuned; the profiles'
    table back to its presets, profile ``PROFILE`` in force."""
    for p in PARAMS[:DRIVE_FIRST]:
        setattr(s, p.field, _DEFAULT_VALUES[p.field])
    preset_profiles(s)
    use_profile(s, C.PROFILE)
    for p in (_WATCHDOG, _FORM):
        setattr(s, p.field, _DEFAULT_VALUES[p.field])


def check(block: bytes) -> str | None:
    """Why ``loadParams`` keeps the defaults for this block (``blank``, ``version``,
    ``crc``, ``range``), or None when it loads it."""
    if all(b == 0xFF for b in block):
        return "blank"
    if block[0] != C.EEPROM_LAYOUT:
        return "version"
    if struct.unpack_from("<H", block, DATA_BYTES)[0] != ee_crc(block):
        return "crc"
    ms = struct.unpack_from("<H", block, _WATCHDOG_AT)[0]
    if (ms < _WATCHDOG.low or ms > _WATCHDOG.high or block[_FORM_AT] > _FORM.high
            or block[_FITTED_AT] > _FITTED.high or block[_PROFILE_AT] > _PROFILE.high):
        return "range"
    for i, p in enumerate(_BLOCK_FLOATS):
        v = struct.unpack_from("<f", block, 1 + 4 * i)[0]
        if not (v >= p.low and v <= p.high):
            return "range"
    return None


def load_params(s: FirmwareState, out: bytearray) -> None:
    """``loadParams``, at the end of ``setup()``: the saved parameters when the block is
    whole (``EVT:PARAMS_LOADED``), else the defaults stay (``EVT:PARAMS_DEFAULT,<why>``)."""
    base = C.EEPROM_PARAMS_ADDR
    block = bytes(s.eeprom[base:base + BLOCK_BYTES])
    why = check(block)
    if why is not None:
        send(s, b"EVT:PARAMS_DEFAULT," + why.encode() + CRLF, out)
        return
    for i, p in enumerate(_FLOATS):
        setattr(s, p.field, struct.unpack_from("<f", block, 1 + 4 * i)[0])
    s.profileTable[:] = struct.unpack_from(f"<{len(s.profileTable)}f", block, _TABLE_AT)
    use_profile(s, block[_PROFILE_AT])
    setattr(s, _WATCHDOG.field, struct.unpack_from("<H", block, _WATCHDOG_AT)[0])
    setattr(s, _FORM.field, block[_FORM_AT])
    setattr(s, _FITTED.field, block[_FITTED_AT])    # at boot: the brake engaged from reset
    send(s, send_event("PARAMS_LOADED"), out)
