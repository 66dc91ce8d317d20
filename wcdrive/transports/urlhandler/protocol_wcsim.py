"""``wcsim://[?speed=1.0&seed=0]``: a simulated chair as a pyserial port.

Behind it runs ``SimulatedBoard``: the bit-exact port of final_control driving the
pymunk plant, paced to the wall clock (``speed`` scales it). Baud rate and framing
settings are accepted and ignored, as on a USB CDC port.
"""

from __future__ import annotations

from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.transports.urlhandler.board_serial import BoardSerial, Option, speed_option, url_options

USAGE = "wcsim://[?speed=S&seed=N]"
OPTIONS = {"speed": Option(1.0, speed_option), "seed": Option(0, int)}


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcsim://...")``: a ``SimulatedBoard`` per open."""

    def _open_board(self, url: str) -> SimulatedBoard:
        _, o, _ = url_options(url, "wcsim", USAGE, OPTIONS)
        return SimulatedBoard(speed=o["speed"], seed=o["seed"])
