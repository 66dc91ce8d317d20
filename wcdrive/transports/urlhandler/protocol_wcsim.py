"""``wcsim://[?speed=1.0&seed=0&chair=chair.toml&world=W&start=x,y,deg&lidar=rplidar_s3]``:
a simulated chair as a pyserial port.

Behind it runs ``SimulatedBoard``: the bit-exact port of final_control driving the
pymunk plant, paced to the wall clock (``speed`` scales it). ``chair`` names a chair
file whose ``[chair]`` table replaces the plant's default parameters
(``wcdrive.plant.params.load_chair``; what ``wcdrive bench identify`` writes).
``world`` puts walls around it (a map_server YAML, a hand-written world's TOML, or a
bundled world's name: hospital_corridor, furnished_room), ``start`` the chair's pose
among them, ``lidar`` a lidar on it (its scans: ``board.lidar``, and
``Wheelchair.scan``). Baud rate and framing settings are accepted and ignored, as on a
USB CDC port.
"""

from __future__ import annotations

from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.plant.params import load_chair
from wcdrive.transports.urlhandler.board_serial import (
    PLACE_OPTIONS,
    PLACE_USAGE,
    BoardSerial,
    Option,
    placed,
    speed_option,
    url_options,
)

USAGE = f"wcsim://[?speed=S&seed=N&chair=chair.toml&{PLACE_USAGE}]"
OPTIONS = {"speed": Option(1.0, speed_option), "seed": Option(0, int), "chair": Option(None, load_chair),
           **PLACE_OPTIONS}


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcsim://...")``: a ``SimulatedBoard`` per open."""

    def _open_board(self, url: str) -> SimulatedBoard:
        _, o, _ = url_options(url, "wcsim", USAGE, OPTIONS)
        return placed("wcsim", o, lambda **place: SimulatedBoard(o["chair"], speed=o["speed"], seed=o["seed"],
                                                                 **place), url)
