"""``Port``: the byte-level interface every backend offers the session.

It is pyserial's, so a ``serial.Serial`` on a device path, anything
``serial.serial_for_url`` opens (``wcsim://``, ``wcavr://``, ``wccan://``, ``wceddie://``) and the
``RecordingPort`` wrapper all are Ports. ``tests/transports/contract/`` runs one suite over every
backend.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from wcdrive.boards.simulation import Simulated


__all__ = ["CancellablePort", "OpenStatePort", "Port", "ResettablePort", "SimulatedPort", "simulation_of"]


@runtime_checkable
class Port(Protocol):
    """A serial-like byte stream to a board.

    - ``read(size)`` returns up to ``size`` bytes, waiting at most ``timeout`` s for
      them (``None``: until ``size`` bytes came); fewer (maybe none) on a timeout.
    - ``write(data)`` queues all of ``data`` and returns its length.
    - ``in_waiting``: bytes that a ``read`` returns without waiting.
    - ``flush()`` waits until written data has left; ``close()`` releases the port
      (twice is fine), and a ``read`` blocked in another thread returns promptly with
      what it has (the ``wc*://`` ports) or raises (pyserial's posix port). On a
      closed port ``read``, ``write`` and ``flush`` raise ``serial.SerialException``
      (``PortNotOpenError``).
    """

    timeout: float | None

    @property
    def in_waiting(self) -> int:
        """Bytes that ``read`` returns without waiting."""

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, waiting at most ``timeout`` s for them."""

    def write(self, data: bytes) -> int | None:
        """Queues all of ``data``; returns its length."""

    def flush(self) -> None:
        """Waits until the written data has left."""

    def close(self) -> None:
        """Releases the port; wakes a ``read`` blocked in another thread."""


@runtime_checkable
class OpenStatePort(Protocol):
    """A ``Port`` that says whether it is open (pyserial's ``is_open``); one without is
    taken as open until it is closed."""

    is_open: bool


@runtime_checkable
class ResettablePort(Protocol):
    """A ``Port`` that can drop what it received and was not yet read (pyserial's
    ``reset_input_buffer``)."""

    def reset_input_buffer(self) -> None:
        """Drops the bytes received and not yet read."""


@runtime_checkable
class CancellablePort(Protocol):
    """A ``Port`` whose ``read`` blocked in another thread can be woken at once
    (pyserial's posix ``cancel_read``)."""

    def cancel_read(self) -> None:
        """Wakes a ``read`` blocked in another thread."""


@runtime_checkable
class SimulatedPort(Protocol):
    """A ``Port`` that may have a simulated board behind it: the ``wc*://`` handlers'
    ports and every ``PortWrapper`` (which asks the port it wraps)."""

    @property
    def simulation(self) -> Simulated | None:
        """The simulated board behind the port (``wcdrive.boards.simulation``), or None
        (a device, a pty, a CAN link, a closed port)."""


def simulation_of(port: Port) -> Simulated | None:
    """The simulated board behind ``port``, through any wrappers; None for a port with
    none."""
    return port.simulation if isinstance(port, SimulatedPort) else None
