"""The host's bytes on the wire to the board: ``wire_schedule`` lays a run's commands
on the UART as both backends deliver them (one byte every ``UART_BYTE_CYCLES``, a
command after the one before it has gone), less the bytes a ``link_cut`` fault
drops, and gives the ``WireSchedule`` the backends send from and the run's figures
are timed by (``_last_byte_before``).

The schedule is made once, before the run, so that both backends see the same bytes
at the same cycles, and the figures that count from a loss of the link count from when
its last byte really arrived.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.port_loop import F_CPU
from wcdrive.plant.faults import Fault

__all__ = ["WireSchedule", "wire_schedule"]


@dataclass(frozen=True)
class WireSchedule:
    """The host's bytes on the wire: ``runs`` of bytes that reach the board, each
    (start cycle, bytes), one byte every ``UART_BYTE_CYCLES``; ``received`` the cycle at
    which each delivered byte has fully arrived, and ``sent`` the start cycle of every
    byte the host sent (delivered or not)."""

    runs: list[tuple[int, bytes]]
    received: np.ndarray
    received_start: np.ndarray


def wire_schedule(commands: list[tuple[int, bytes]], faults: tuple[Fault, ...] = ()) -> WireSchedule:
    """Lays the host's commands ((cycle, bytes), in order) on the wire as both boards do
    (a command starts when it is sent or when the previous one has gone) and drops the
    bytes whose transmission starts while a ``link_cut`` acts."""
    cuts = [f.cycles(F_CPU) for f in faults if f.kind == "link_cut"]
    runs: list[tuple[int, bytes]] = []
    received: list[int] = []
    starts: list[int] = []
    free = 0
    for cycle, data in commands:
        start = max(cycle, free)
        free = start + len(data) * UART_BYTE_CYCLES
        run_start, run = 0, bytearray()
        for i, byte in enumerate(data):
            at = start + i * UART_BYTE_CYCLES
            lost = any(lo <= at and (hi is None or at < hi) for lo, hi in cuts)
            if lost:
                if run:
                    runs.append((run_start, bytes(run)))
                    run = bytearray()
                continue
            if not run:
                run_start = at
            run.append(byte)
            starts.append(at)
            received.append(at + UART_BYTE_CYCLES)
        if run:
            runs.append((run_start, bytes(run)))
    return WireSchedule(runs, np.array(received, dtype=np.int64), np.array(starts, dtype=np.int64))


def _last_byte_before(wire: WireSchedule, at: float) -> float:
    """s: when the last byte whose transmission started before ``at`` reached the
    board (0 if none did)."""
    before = np.flatnonzero(wire.received_start < round(at * F_CPU))
    return float(wire.received[before[-1]]) / F_CPU if before.size else 0.0
