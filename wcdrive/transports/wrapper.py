"""``PortWrapper``: a ``Port`` around another ``Port``, with hooks on what goes through.

    class Spy(PortWrapper):
        def on_sent(self, data: bytes) -> None:
            print("host ->", data)

        def on_read(self, data: bytes) -> bytes:
            print("board ->", data)
            return data

Every ``Port`` method goes to the wrapped port (``port``); a subclass overrides a hook,
not the method. ``RecordingPort`` (a log of both ways), the ROS tap
(``wcdrive.ros2.bridge.TapPort``) and ``FaultyPort`` (lost, garbled, late bytes and a
dead link) are wrappers.

The model is pyserial's ``spy://`` handler, which inherits the native port and
intercepts ``write`` and ``read``. A wrapper holds its port instead, so it works
around any ``Port`` (``wcsim://``, a device, another wrapper), and wrappers stack:
``TapPort(RecordingPort(port))``.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

from wcdrive.transports.port import OpenStatePort, Port, ResettablePort, simulation_of

if TYPE_CHECKING:
    from wcdrive.boards.simulation import Simulated

__all__ = ["PortWrapper"]


class PortWrapper:
    """A ``Port`` that delegates to ``port``, calling hooks on the way.

    - ``write(data)``: ``on_write(data)`` gives the bytes to write instead (default:
      ``data``; empty: nothing is written); the wrapped port writes them, then
      ``on_sent(them)``. Returns ``len(data)``: the caller's bytes were all taken.
    - ``read(size)``: the wrapped port reads, then ``on_read(what came)`` (called with
      ``b""`` too) gives what the caller gets.
    - ``close()``: the wrapped port closes, then ``on_close()``.
    - ``timeout`` (read and set), ``in_waiting``, ``is_open`` and ``flush`` are the
      wrapped port's; ``simulation`` too (the simulated board behind it, None for a
      device), and ``reset_input_buffer`` where it has one.

    A hook that raises makes its call raise. The hooks run in the caller's thread (the
    session's reader thread for ``read``), so a hook that keeps state shared with
    other threads locks it.
    """

    def __init__(self, port: Port) -> None:
        self.port = port

    # ---- hooks ----------------------------------------------------------------------
    def on_write(self, data: bytes) -> bytes:
        """What to hand the wrapped port for ``data`` (default: ``data`` itself)."""
        return data

    def on_sent(self, data: bytes) -> None:
        """Called after the wrapped port took ``data`` (what ``on_write`` gave)."""

    def on_read(self, data: bytes) -> bytes:
        """What the caller gets for ``data``, the bytes the wrapped port read (default:
        ``data`` itself)."""
        return data

    def on_close(self) -> None:
        """Called after the wrapped port closed."""

    # ---- the Port -------------------------------------------------------------------
    @property
    def timeout(self) -> float | None:
        """The wrapped port's ``timeout``."""
        return self.port.timeout

    @timeout.setter
    def timeout(self, value: float | None) -> None:
        self.port.timeout = value

    @property
    def in_waiting(self) -> int:
        """The wrapped port's."""
        return int(self.port.in_waiting)

    @property
    def is_open(self) -> bool:
        """The wrapped port's (pyserial's attribute; True for a port without one)."""
        return bool(self.port.is_open) if isinstance(self.port, OpenStatePort) else True

    @property
    def simulation(self) -> Simulated | None:
        """The simulated board behind the wrapped port (``simulation_of``), or None."""
        return simulation_of(self.port)

    @property
    def board(self) -> Simulated | None:
        """Deprecated: ``simulation``, the typed handle on the simulated board (this
        returns the same object, with a ``DeprecationWarning``)."""
        warnings.warn("PortWrapper.board is deprecated: use .simulation (or "
                      "wcdrive.transports.port.simulation_of(port))", DeprecationWarning, stacklevel=2)
        return self.simulation

    def write(self, data: bytes) -> int | None:
        """``on_write``, the wrapped port's ``write``, ``on_sent``; returns ``len(data)``."""
        data = bytes(data)
        out = self.on_write(data)
        if out:
            self.port.write(out)
            self.on_sent(out)
        return len(data)

    def read(self, size: int = 1) -> bytes:
        """The wrapped port's ``read``, through ``on_read``."""
        return self.on_read(self.port.read(size))

    def flush(self) -> None:
        """Flushes the wrapped port."""
        self.port.flush()

    def reset_input_buffer(self) -> None:
        """Drops what the wrapped port received and not yet read (where it can)."""
        if isinstance(self.port, ResettablePort):
            self.port.reset_input_buffer()

    def close(self) -> None:
        """Closes the wrapped port, then ``on_close``."""
        self.port.close()
        self.on_close()
