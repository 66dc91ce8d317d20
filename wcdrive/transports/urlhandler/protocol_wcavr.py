"""``wcavr://[path/to.elf][?realtime=0&speed=S&plant=0]``: the compiled firmware in simavr as
a pyserial port, the pymunk chair behind its pins (``plant=0``: wheels still).

The virtual Mega runs at real time by default, as a real board does, so that a
program paced by the wall clock sees the chair a real one would be. ``speed=S`` runs
it at S times real time; ``realtime=0`` runs it as fast as simavr can (about 1.5x
real time with the chair on this machine's CI; tests that do not depend on the
wall clock use it). The ELF defaults to firmware/final_control, built on first use.
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import SerialException

from wcdrive.transports.urlhandler.board_serial import BoardSerial

_USAGE = "wcavr://[elf][?realtime=0&speed=S&plant=0]"


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcavr://...")``: a ``MegaBoard`` per open."""

    def _open_board(self, url: str):
        from wcdrive.boards.simavr.mega_board import MegaBoard

        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "wcavr":
            raise SerialException(f"expected {_USAGE}, got {url!r}")
        options = {k: v[0] for k, v in urllib.parse.parse_qs(parts.query, True).items()}
        unknown = set(options) - {"realtime", "plant", "speed"}
        if unknown:
            raise SerialException(f"wcavr://: unknown option {sorted(unknown)[0]!r} ({_USAGE})")
        realtime = options.get("realtime", "1") not in ("0", "false")
        try:
            speed = float(options.get("speed", "1"))
        except ValueError:
            raise SerialException(f"wcavr://: speed must be a number ({_USAGE})") from None
        if not 0.01 <= speed <= 1000.0:
            raise SerialException("wcavr:// speed must be within 0.01 .. 1000")
        if not realtime and "speed" in options:
            raise SerialException("wcavr://: realtime=0 runs flat out; give speed= or realtime=0, not both")
        elf = (parts.netloc + parts.path) or None
        return MegaBoard(elf, realtime=realtime, speed=speed,
                         plant=options.get("plant", "1") not in ("0", "false"))
