"""``wceddie://[?speed=1.0&seed=0&eol=firmware]``: a simulated Eddie board as a pyserial port
(pyserial finds it through the ``wcdrive.serial_urls`` entry point ``wceddie``).

Behind it runs ``wcdrive.eddie.board.EddieSimBoard``: the model of the Eddie control
board's firmware driving the Eddie configuration of the pymunk plant, paced to the
wall clock (``speed`` scales it). ``eol=tolerant`` makes LF end a line too (the
firmware source stores it: docs/eddie.md). Baud rate and framing are accepted and
ignored, as on a USB serial port.
"""

from __future__ import annotations

from wcdrive.eddie.board import EddieSimBoard
from wcdrive.transports.urlhandler.board_serial import (
    BoardSerial,
    Option,
    choice_option,
    speed_option,
    url_options,
)

USAGE = "wceddie://[?speed=S&seed=N&eol=firmware|tolerant]"
OPTIONS = {"speed": Option(1.0, speed_option), "seed": Option(0, int),
           "eol": Option("firmware", choice_option("firmware", "tolerant"))}


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wceddie://...")``: an ``EddieSimBoard`` per open."""

    def _open_board(self, url: str) -> EddieSimBoard:
        _, o, _ = url_options(url, "wceddie", USAGE, OPTIONS)
        return EddieSimBoard(speed=o["speed"], seed=o["seed"], eol=o["eol"])
