"""``wcsim://[?speed=1.0&seed=0]``: a simulated chair as a pyserial port.

Behind it runs ``SimulatedBoard``: the bit-exact port of final_control driving the
pymunk plant, paced to the wall clock (``speed`` scales it). Baud rate and framing
settings are accepted and ignored, as on a USB CDC port.
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import SerialException

from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.transports.urlhandler.board_serial import BoardSerial


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcsim://...")``: a ``SimulatedBoard`` per open."""

    def _open_board(self, url: str) -> SimulatedBoard:
        speed, seed = self._parse(url)
        return SimulatedBoard(speed=speed, seed=seed)

    @staticmethod
    def _parse(url: str) -> tuple[float, int]:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "wcsim":
            raise SerialException(f"expected wcsim://[?speed=S&seed=N], got {url!r}")
        speed, seed = 1.0, 0
        for option, values in urllib.parse.parse_qs(parts.query, True).items():
            try:
                if option == "speed":
                    speed = float(values[0])
                elif option == "seed":
                    seed = int(values[0])
                else:
                    raise ValueError(f"unknown option {option!r}")
            except ValueError as exc:
                raise SerialException(f"wcsim://[?speed=S&seed=N]: {exc}") from exc
        if not 0.01 <= speed <= 1000.0:
            raise SerialException("wcsim:// speed must be within 0.01 .. 1000")
        return speed, seed
