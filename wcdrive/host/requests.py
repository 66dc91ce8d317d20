"""Typed requests: what the host asks of the board and awaits an answer to (``Request``,
one ``RequestKind`` each), built where the command is made.

A request's kind decides how the session recovers when its answer is lost (read the
e-stop flag back, read the parameter back, ask again, send again); its wire form
(``Request.command``) is only what goes into the frame. So the session never reads
a command's bytes to learn what it means.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from wcdrive.protocol.codec import DEFAULTS, ESTOP, RESET, SAVE, encode_get, encode_set

__all__ = ["Request", "RequestKind"]


class RequestKind(enum.Enum):
    """What a request asks the board to do; the value is its word on the wire."""

    GET = "get"
    SET = "set"
    SAVE = "save"
    DEFAULTS = "defaults"
    ESTOP = "estop"
    RESET = "reset"


#: The commands without arguments, as the codec spells them (without the line end).
_BARE = {RequestKind.SAVE: SAVE, RequestKind.DEFAULTS: DEFAULTS, RequestKind.ESTOP: ESTOP,
         RequestKind.RESET: RESET}


@dataclass(frozen=True, slots=True)
class Request:
    """One request: its ``kind``, the parameter it reads or sets (``param``, for GET
    and SET) and, for SET, the value as the text the board reads (``text``). Build it
    with the class methods, which check what the codec checks."""

    kind: RequestKind
    param: str = ""
    text: bytes = b""

    @classmethod
    def get(cls, name: str) -> Request:
        """Read the parameter ``name`` (ValueError for an unknown one)."""
        encode_get(name)
        return cls(RequestKind.GET, name)

    @classmethod
    def set(cls, name: str, value: float) -> Request:
        """Set the parameter ``name`` to ``value`` (ValueError out of its range), as
        the codec writes it."""
        return cls.set_text(name, encode_set(name, value).partition(b"=")[2])

    @classmethod
    def set_text(cls, name: str, text: bytes) -> Request:
        """Set ``name`` to ``text`` as it is, unchecked: for tools and tests that send
        what the codec refuses (the board answers ``NAK``)."""
        return cls(RequestKind.SET, name, text)

    @classmethod
    def save(cls) -> Request:
        """Store the parameters in force in the board's EEPROM."""
        return cls(RequestKind.SAVE)

    @classmethod
    def defaults(cls) -> Request:
        """Put every parameter back to the firmware's default."""
        return cls(RequestKind.DEFAULTS)

    @classmethod
    def estop(cls) -> Request:
        """Latch the e-stop."""
        return cls(RequestKind.ESTOP)

    @classmethod
    def reset(cls) -> Request:
        """Release the e-stop and any latched fault."""
        return cls(RequestKind.RESET)

    @property
    def command(self) -> bytes:
        """The command as it goes into the frame: ``get:<name>``, ``set:<name>=<text>``,
        ``estop``, ..."""
        if self.kind is RequestKind.GET:
            return b"get:" + self.param.encode()
        if self.kind is RequestKind.SET:
            return b"set:" + self.param.encode() + b"=" + self.text
        return _BARE[self.kind].rstrip(b"\n")

    def read_back(self) -> Request:
        """The GET that reads the parameter a GET or SET is about."""
        return Request(RequestKind.GET, self.param)
