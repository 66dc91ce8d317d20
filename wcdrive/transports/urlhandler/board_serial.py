"""A board or link as a pyserial port: the part every ``wc*://`` handler shares.

Subclasses open their board (a ``ThreadedBoard``, or the CAN link) from the URL in
``_open_board``; every handler's query is parsed by ``url_options`` here, and nowhere
else. Baud rate and framing settings are accepted and ignored, as on a USB CDC port.
"""

from __future__ import annotations

import math
import time
import urllib.parse
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes

from wcdrive.boards.simulation import Simulated

if TYPE_CHECKING:                     # a real chair's link (can://) loads no simulator
    from wcdrive.plant.lidar import Lidar
    from wcdrive.plant.world import World


class BoardLike(Protocol):
    """What a handler opens: a ``ThreadedBoard`` or a ``CanLink``."""

    def start(self) -> Any:
        """Starts the board (or link) and returns it."""

    def close(self) -> None:
        """Stops it; wakes a ``read`` blocked in another thread."""

    @property
    def closed(self) -> bool:
        """True once ``close`` was called."""

    @property
    def in_waiting(self) -> int:
        """Bytes received and not yet read."""

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        """Up to ``size`` bytes; waits up to ``timeout`` s for the first."""

    def write(self, data: bytes) -> int:
        """Sends ``data``; returns its length."""

    def reset_input(self) -> None:
        """Drops what was received and not yet read."""

    @property
    def rx_dropped(self) -> int:
        """Bytes received and dropped because the receive buffer was full."""


_B = TypeVar("_B")


@dataclass(frozen=True)
class Option:
    """One ``?name=value`` of a URL: its default and how its text is read (``parse``
    raises ``ValueError`` on a bad value)."""

    default: Any
    parse: Callable[[str], Any]


def speed_option(text: str) -> float:
    """A wall-clock speed factor within 0.01 .. 1000."""
    speed = float(text)
    if not 0.01 <= speed <= 1000.0:
        raise ValueError("speed must be within 0.01 .. 1000")
    return speed


def flag_option(text: str) -> bool:
    """``0``/``false`` off, anything else on."""
    return text not in ("0", "false")


def world_option(text: str) -> World:
    """A world's file or a bundled world's name (``wcdrive.plant.world.world_named``)."""
    from wcdrive.plant.world import world_named

    return world_named(text)


def start_option(text: str) -> tuple[float, float, float]:
    """``x,y,heading_deg``: the chair's start pose in the world (m, m, degrees); returned
    with the heading in radians."""
    parts = text.split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError("start is x,y,heading_deg: three finite numbers")
    return values[0], values[1], math.radians(values[2])


def lidar_option(text: str) -> Lidar:
    """A lidar model's name on the seed's mount (``wcdrive.plant.lidar.lidar_named``)."""
    from wcdrive.plant.lidar import lidar_named

    return lidar_named(text)


#: The options that put a simulated board's chair in a world (``wcsim://``, ``wcavr://``).
PLACE_USAGE = "world=W&start=x,y,deg&lidar=rplidar_s3"
PLACE_OPTIONS = {"world": Option(None, world_option), "start": Option((0.0, 0.0, 0.0), start_option),
                 "lidar": Option(None, lidar_option)}


def placed(scheme: str, options: Mapping[str, Any], make: Callable[..., _B]) -> _B:
    """The board ``make`` builds with the ``PLACE_OPTIONS`` of ``options`` as keywords; a
    chair that cannot stand where ``start`` puts it in its ``world`` is a
    ``SerialException`` that says to give another start."""
    try:
        return make(**{name: options[name] for name in PLACE_OPTIONS})
    except ValueError as exc:
        if options["world"] is None:
            raise
        raise SerialException(f"{scheme}://: {exc}: give start=x,y,heading_deg where the chair stands free"
                              ) from exc


def choice_option(*choices: str) -> Callable[[str], str]:
    """One of ``choices``."""
    def parse(text: str) -> str:
        if text not in choices:
            raise ValueError(f"must be one of {', '.join(choices)}")
        return text
    return parse


def url_options(url: str, scheme: str, usage: str, options: Mapping[str, Option]
                ) -> tuple[urllib.parse.SplitResult, dict[str, Any], frozenset[str]]:
    """The URL split, its query read against ``options`` (each default where absent),
    and the names the query gave. A wrong scheme, an unknown option or a bad value is a ``SerialException``
    that names it and shows ``usage``."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != scheme:
        raise SerialException(f"expected {usage}, got {url!r}")
    values = {name: option.default for name, option in options.items()}
    given = urllib.parse.parse_qs(parts.query, True)
    for name, texts in given.items():
        if name not in options:
            raise SerialException(f"{scheme}://: unknown option {name!r} ({usage})")
        try:
            values[name] = options[name].parse(texts[-1])
        except ValueError as exc:
            raise SerialException(f"{scheme}://: {name}={texts[-1]!r}: {exc} ({usage})") from exc
    return parts, values, frozenset(given)


class BoardSerial(SerialBase):
    """pyserial's ``SerialBase`` over a ``BoardLike``; ``read`` honours ``timeout``."""

    BAUDRATES = (9600, 19200, 38400, 57600, 115200, 230400)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.board: BoardLike | None = None
        self.is_open: bool = False
        super().__init__(*args, **kwargs)

    def _open_board(self, url: str) -> BoardLike:
        raise NotImplementedError

    def open(self) -> None:
        """Opens the board named by the URL (``port``); a new board each time."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.board = self._open_board(self.portstr).start()
        self.is_open = True

    def close(self) -> None:
        """Closes the board; safe to call twice, and wakes a ``read`` blocked in another
        thread."""
        board, self.board = self.board, None
        self.is_open = False
        if board is not None:
            board.close()

    def _reconfigure_port(self) -> None:
        pass

    @property
    def simulation(self) -> Simulated | None:
        """The simulated board behind the port (``wcdrive.boards.simulation``); None
        when closed or for a link that is not one (``wccan://``)."""
        board = self.board
        return board if isinstance(board, Simulated) else None

    def _board(self) -> BoardLike:
        """The open board, or ``PortNotOpenError``. Callers keep the object they got:
        another thread may close the port meanwhile."""
        board = self.board
        if not self.is_open or board is None:
            raise PortNotOpenError()
        return board

    @property
    def in_waiting(self) -> int:
        """Bytes received and not yet read."""
        return self._board().in_waiting

    @property
    def rx_dropped(self) -> int:
        """Bytes the board sent that were dropped since the port was opened, because
        its receive buffer was full: like a serial driver's, it holds a bounded amount
        (4096 bytes on ``wcavr://``, a Linux tty's; more on ``wcsim://``, see
        ``sim_board.rx_capacity``) for a program that does not read."""
        return self._board().rx_dropped

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes within ``timeout`` (``None``: until ``size`` came). A read
        blocked when another thread closes the port returns what it has; the next
        call raises ``PortNotOpenError``."""
        board = self._board()
        data = bytearray()
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while len(data) < size:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            chunk = board.read(size - len(data), timeout=left)
            data += chunk
            if not chunk and (board.closed or (deadline is not None and time.monotonic() >= deadline)):
                break
        return bytes(data)

    def write(self, data: Any) -> int:
        """Hands all of ``data`` to the board; returns its length."""
        return self._board().write(to_bytes(data))

    def flush(self) -> None:
        """Nothing to wait for: ``write`` hands the bytes to the board (or the bus) at
        once. Raises ``PortNotOpenError`` on a closed port, as pyserial's ports do."""
        self._board()

    def reset_input_buffer(self) -> None:
        """Drops what was received and not yet read."""
        self._board().reset_input()

    def reset_output_buffer(self) -> None:
        """Nothing to drop: written bytes are with the board already."""
        self._board()

    @property
    def cts(self) -> bool:
        """Always set, as on a USB CDC port."""
        return True

    @property
    def dsr(self) -> bool:
        """Always set, as on a USB CDC port."""
        return True

    @property
    def ri(self) -> bool:
        """Never set."""
        return False

    @property
    def cd(self) -> bool:
        """Always set, as on a USB CDC port."""
        return True

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass
