"""``wcavr://[path/to.elf][?realtime=0&speed=S&plant=0&chair=chair.toml&world=W&start=x,y,deg``
``&lidar=rplidar_s3]``: the compiled firmware in simavr as a pyserial port, the pymunk chair behind its pins
(``plant=0``: wheels still; ``chair``: a chair file whose ``[chair]`` table replaces
the plant's default parameters, ``wcdrive.plant.params.load_chair``; ``world``,
``start`` and ``lidar`` as ``wcsim://``'s).

The virtual Mega runs at real time by default, as a real board does, so that a
program paced by the wall clock sees the chair a real one would be. ``speed=S`` runs
it at S times real time; ``realtime=0`` runs it as fast as simavr can (about 1.5x
real time with the chair on this machine's CI; tests that do not depend on the
wall clock use it). The ELF defaults to firmware/final_control, built on first use.
"""

from __future__ import annotations

from serial.serialutil import SerialException

from wcdrive.plant.params import load_chair
from wcdrive.transports.urlhandler.board_serial import (
    PLACE_OPTIONS,
    PLACE_USAGE,
    BoardSerial,
    Option,
    flag_option,
    placed,
    speed_option,
    url_options,
)

USAGE = f"wcavr://[elf][?realtime=0&speed=S&plant=0&chair=chair.toml&{PLACE_USAGE}]"
OPTIONS = {"realtime": Option(True, flag_option), "speed": Option(1.0, speed_option),
           "plant": Option(True, flag_option), "chair": Option(None, load_chair), **PLACE_OPTIONS}


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcavr://...")``: a ``MegaBoard`` per open."""

    def _open_board(self, url: str):
        from wcdrive.boards.simavr.mega_board import MegaBoard

        parts, o, given = url_options(url, "wcavr", USAGE, OPTIONS)
        if not o["realtime"] and "speed" in given:
            raise SerialException("wcavr://: realtime=0 runs flat out; give speed= or realtime=0, not both")
        if not o["plant"] and "chair" in given:
            raise SerialException("wcavr://: plant=0 has no chair; give chair= or plant=0, not both")
        if not o["plant"] and given & PLACE_OPTIONS.keys():
            raise SerialException("wcavr://: plant=0 has no chair to put in a world or carry a lidar")
        elf = (parts.netloc + parts.path) or None
        plant = o["chair"] if o["plant"] and o["chair"] is not None else o["plant"]
        return placed("wcavr", o, lambda **place: MegaBoard(elf, realtime=o["realtime"], speed=o["speed"],
                                                            plant=plant, **place), url)
