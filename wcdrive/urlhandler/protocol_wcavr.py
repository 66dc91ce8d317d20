"""``wcavr://[path/to.elf][?realtime=1&plant=0]``: the compiled firmware in simavr as a
pyserial port, the pymunk chair behind its pins (``plant=0``: wheels still).

Without ``realtime=1`` the virtual Mega runs as fast as it can (about 1.5x real time
with the chair); the ELF defaults to firmware/final_control, built on first use.
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import SerialException

from wcdrive.urlhandler.board_serial import BoardSerial


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wcavr://...")``: a ``MegaBoard`` per open."""

    def _open_board(self, url: str):
        from wcdrive.boards.simavr.mega_board import MegaBoard

        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "wcavr":
            raise SerialException(f"expected wcavr://[elf][?realtime=1&plant=0], got {url!r}")
        options = {k: v[0] for k, v in urllib.parse.parse_qs(parts.query, True).items()}
        unknown = set(options) - {"realtime", "plant"}
        if unknown:
            raise SerialException(f"wcavr://: unknown option {sorted(unknown)[0]!r}")
        elf = (parts.netloc + parts.path) or None
        return MegaBoard(elf, realtime=options.get("realtime", "0") in ("1", "true"),
                         plant=options.get("plant", "1") not in ("0", "false"))
