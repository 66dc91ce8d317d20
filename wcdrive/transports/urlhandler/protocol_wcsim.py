"""``wcsim://[?speed=1.0&seed=0&chair=chair.toml]``: a simulated chair as a pyserial port.

Behind it runs ``SimulatedBoard``: the bit-exact port of final_control driving the
pymunk plant, paced to the wall clock (``speed`` scales it). ``chair`` names a chair
file whose ``[chair]`` table replaces the plant's default parameters
(``wcdrive.plant.params.load_chair``; what ``wcdrive bench identify`` writes). Baud
rate and framing settings are accepted and ignored, as on a USB CDC port.
"""

from __future__ import annotations

from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.plant.params import load_chair
from wcdrive.transports.urlhandler.board_serial import BoardSerial, Option, speed_option, url_options

USAGE = "wcsim://[?speed=S&seed=N&chair=chair.toml]"
OPTIONS = {"speed": Option(1.0, speed_option), "seed": Option(0, int), "chair": Option(None, load_chair)}


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcsim://...")``: a ``SimulatedBoard`` per open."""

    def _open_board(self, url: str) -> SimulatedBoard:
        _, o, _ = url_options(url, "wcsim", USAGE, OPTIONS)
        return SimulatedBoard(o["chair"], speed=o["speed"], seed=o["seed"])
