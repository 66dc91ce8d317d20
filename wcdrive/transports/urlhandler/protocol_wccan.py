"""``wccan://<interface>/<channel>``: a chair on a CAN bus as a pyserial port.

The host end of ``protocol/CAN.md``: protocol lines written to the port become command
frames, and the chair's frames come back as the board's lines, so anything that
speaks the serial protocol talks to a chair behind a ``wcdrive can-gateway``.
``interface`` and ``channel`` are python-can's: ``wccan://socketcan/can0`` on a real
bus; ``wccan://virtual/chair`` reaches a gateway in the same process only (python-can's
virtual bus is per process).
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import SerialException

from wcdrive.errors import WcdriveConnectionError
from wcdrive.transports.can_link import CanLink, open_can_link
from wcdrive.transports.urlhandler.board_serial import BoardSerial


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wccan://...")``."""

    def _open_board(self, url: str) -> CanLink:
        parts = urllib.parse.urlsplit(url)
        channel = parts.path.lstrip("/")
        if parts.scheme != "wccan" or not parts.netloc or not channel or parts.query:
            raise SerialException(f"expected wccan://<interface>/<channel>, got {url!r}")
        try:
            return open_can_link(parts.netloc, channel)
        except WcdriveConnectionError as exc:
            raise SerialException(str(exc)) from exc
