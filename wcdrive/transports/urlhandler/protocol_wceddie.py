"""``wceddie://[?speed=1.0&seed=0&eol=firmware]``: a simulated Eddie board as a pyserial port.

Behind it runs ``wcdrive.eddie.board.EddieSimBoard``: the model of the Eddie control
board's firmware driving the Eddie configuration of the pymunk plant, paced to the
wall clock (``speed`` scales it). ``eol=tolerant`` makes LF end a line too (the
firmware source stores it: docs/eddie.md). Baud rate and framing are accepted and
ignored, as on a USB serial port.
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import SerialException

from wcdrive.eddie.board import EddieSimBoard
from wcdrive.transports.urlhandler.board_serial import BoardSerial

USAGE = "wceddie://[?speed=S&seed=N&eol=firmware|tolerant]"


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wceddie://...")``: an ``EddieSimBoard`` per open."""

    def _open_board(self, url: str) -> EddieSimBoard:
        speed, seed, eol = self._parse(url)
        return EddieSimBoard(speed=speed, seed=seed, eol=eol)

    @staticmethod
    def _parse(url: str) -> tuple[float, int, str]:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "wceddie":
            raise SerialException(f"expected {USAGE}, got {url!r}")
        speed, seed, eol = 1.0, 0, "firmware"
        for option, values in urllib.parse.parse_qs(parts.query, True).items():
            try:
                if option == "speed":
                    speed = float(values[0])
                elif option == "seed":
                    seed = int(values[0])
                elif option == "eol" and values[0] in ("firmware", "tolerant"):
                    eol = values[0]
                else:
                    raise ValueError(f"unknown option {option}={values[0]!r}")
            except ValueError as exc:
                raise SerialException(f"{USAGE}: {exc}") from exc
        if not 0.01 <= speed <= 1000.0:
            raise SerialException("wceddie:// speed must be within 0.01 .. 1000")
        return speed, seed, eol
