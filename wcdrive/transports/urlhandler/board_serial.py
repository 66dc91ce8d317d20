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
    from wcdrive.plant.lidar_mount import LidarMount
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


def lidar_mount_option(text: str) -> LidarMount:
    """``x,y,z,roll,pitch,yaw`` (m and degrees): the lidar's mount
    (``wcdrive.plant.lidar_mount.parse_mount``)."""
    from wcdrive.plant.lidar_mount import parse_mount

    return parse_mount(text)


def lidar_driver_option(text: str) -> str:
    """The lidar's ROS 2 driver (``wcdrive.plant.lidar_driver.DRIVERS``)."""
    from wcdrive.plant.lidar_driver import DRIVERS

    if text not in DRIVERS:
        raise ValueError(f"must be one of {', '.join(DRIVERS)}")
    return text


def lidar_flag_option(text: str) -> bool:
    """``true`` or ``false`` (``wcdrive.plant.lidar.flag``)."""
    from wcdrive.plant.lidar import flag

    return flag(text)


#: The lidar's details (None: not given): its mount, its driver and the driver's two
#: parameters; each needs ``lidar=`` or a chair file's ``[lidar]`` table (``placed_lidar``).
LIDAR_DETAILS = {"lidar_mount": Option(None, lidar_mount_option),
                 "lidar_driver": Option(None, lidar_driver_option),
                 "lidar_inverted": Option(None, lidar_flag_option),
                 "lidar_angle_compensate": Option(None, lidar_flag_option)}
#: The options that put a simulated board's chair in a world (``wcsim://``, ``wcavr://``).
PLACE_USAGE = ("world=W&start=x,y,deg&lidar=rplidar_s3&lidar_mount=x,y,z,roll,pitch,yaw"
               "&lidar_driver=sllidar_ros2|rplidar_ros&lidar_inverted=B&lidar_angle_compensate=B")
PLACE_OPTIONS = {"world": Option(None, world_option), "start": Option((0.0, 0.0, 0.0), start_option),
                 "lidar": Option(None, lidar_option), **LIDAR_DETAILS}


def chair_file_lidar(url: str) -> Lidar | None:
    """The lidar of the ``[lidar]`` table of the chair file a URL's ``chair=`` names
    (``wcdrive.plant.params.load_chair_lidar``), or None."""
    texts = urllib.parse.parse_qs(urllib.parse.urlsplit(url).query, True).get("chair")
    if not texts:
        return None
    from wcdrive.plant.params import load_chair_lidar

    return load_chair_lidar(texts[-1])


def placed_lidar(scheme: str, options: Mapping[str, Any], url: str = "") -> Lidar | None:
    """The lidar of ``options``: ``lidar=``'s model on the seed's mount, else the chair
    file's (``chair_file_lidar``), with the ``LIDAR_DETAILS`` given in place of that
    lidar's own (``wcdrive.plant.lidar.configured_lidar``). A detail with no lidar to
    apply to is a ``SerialException`` that names it, as is a bad ``[lidar]`` table."""
    try:
        lidar: Lidar | None = options["lidar"] or chair_file_lidar(url)
    except ValueError as exc:
        raise SerialException(f"{scheme}://: chair=: {exc}") from exc
    given = {name: options[name] for name in LIDAR_DETAILS if options.get(name) is not None}
    if lidar is None:
        if given:
            names = ", ".join(given)
            raise SerialException(f"{scheme}://: {names} needs lidar=rplidar_s3 (a lidar to mount)")
        return None
    from wcdrive.plant.lidar import configured_lidar

    return configured_lidar(lidar.model.name, given.get("lidar_mount", lidar.mount),
                            given.get("lidar_driver", lidar.driver.name),
                            given.get("lidar_inverted", lidar.mount.driver_inverted),
                            given.get("lidar_angle_compensate", lidar.driver.angle_compensate))


def placed(scheme: str, options: Mapping[str, Any], make: Callable[..., _B], url: str = "") -> _B:
    """The board ``make`` builds with the chair's place as keywords (``world``, ``start``,
    and ``lidar``: ``placed_lidar`` of ``options`` and the ``url`` they came from); a
    chair that cannot stand where ``start`` puts it in its ``world`` is a
    ``SerialException`` that says to give another start."""
    place = {"world": options["world"], "start": options["start"],
             "lidar": placed_lidar(scheme, options, url)}
    try:
        return make(**place)
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
