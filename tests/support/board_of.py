"""White-box access for tests: the simulated board object behind a port, through any
``PortWrapper`` (the library itself reaches a simulation only through its typed
handle, ``wcdrive.transports.port.simulation_of``)."""

from __future__ import annotations

from typing import Any

from wcdrive.transports.wrapper import PortWrapper


def board_of(port: Any) -> Any:
    """The board object (``SimulatedBoard``, ``MegaBoard``, ...) behind ``port``."""
    while isinstance(port, PortWrapper):
        port = port.port
    return port.board
