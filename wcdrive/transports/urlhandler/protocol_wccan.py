"""``wccan://<interface>/<channel>``: a chair on a CAN bus as a pyserial port.

The host end of ``protocol/CAN.md``: protocol lines written to the port become command
frames, and the chair's frames come back as the board's lines, so anything that
speaks the serial protocol talks to a chair behind a ``wcdrive can-gateway``.
``interface`` and ``channel`` are python-can's: ``wccan://socketcan/can0`` on a real
bus; ``wccan://virtual/chair`` reaches a gateway in the same process only (python-can's
virtual bus is per process).
"""

from __future__ import annotations

from serial.serialutil import SerialException

from wcdrive.errors import WcdriveConnectionError
from wcdrive.transports.can_link import CanLink, open_can_link
from wcdrive.transports.urlhandler.board_serial import BoardSerial, url_options

USAGE = "wccan://<interface>/<channel>"


class Serial(BoardSerial):
    """pyserial's ``serial_for_url("wccan://...")``."""

    def _open_board(self, url: str) -> CanLink:
        parts, _, _ = url_options(url, "wccan", USAGE, {})
        channel = parts.path.lstrip("/")
        if not parts.netloc or not channel:
            raise SerialException(f"expected {USAGE}, got {url!r}")
        try:
            return open_can_link(parts.netloc, channel)
        except WcdriveConnectionError as exc:
            raise SerialException(str(exc)) from exc
