"""The logs a scenario run fills as it goes: ``TickLog``, a row of numbers per control
tick (the plant's state, the host's estimates, the firmware's setpoints, speeds, duties
and counts), read back as arrays by column; and ``LineLog``, the board's TX stream cut
into stamped lines, its ``EVT:`` and ``BOOT:`` lines kept apart.

Both keep their rows flat (an ``array('d')``, parallel lists) rather than an object
per row: a run pauses the cyclic garbage collector (``cyclic_gc_paused`` in
``wcdrive.sim.runner``), and rows that are not objects leave it nothing to scan when
it comes back on.
"""

from __future__ import annotations

import math
from array import array

import numpy as np

from wcdrive.boards.port_loop import F_CPU
from wcdrive.plant import Plant
from wcdrive.sim.host import SimHost

__all__ = ["LineLog", "TickLog"]

#: The tick log's columns and their widths, in the order ``TickLog.add`` writes them.
_LOG_COLUMNS = (("tick_time", 1), ("truth", 3), ("odom_wheel", 3), ("odom_velocity", 3), ("odom_gyro", 3),
                ("setpoint", 2), ("measured", 2), ("wheel_speed", 2), ("pwm", 2), ("caster", 2),
                ("counts", 2), ("odom_ekf", 3), ("odom_ekf_vel", 3), ("winding_temp", 2),
                ("battery", 2))
_LOG_WIDTH = sum(width for _, width in _LOG_COLUMNS)
#: Where each column starts in a row.
_LOG_OFFSETS = {name: sum(w for _, w in _LOG_COLUMNS[:i]) for i, (name, _) in enumerate(_LOG_COLUMNS)}


class TickLog:
    """A row of numbers per control tick, kept flat in one ``array('d')``: no object
    per row outlives the tick, so the run leaves the garbage collector (paused for
    the run, ``cyclic_gc_paused``) nothing to scan when it comes back on."""

    def __init__(self) -> None:
        self._flat = array("d")
        self.tick_cycles: list[int] = []

    def add(self, cycle: int, plant: Plant, host: SimHost, setpoint, measured, pwm, counts) -> None:
        """The row of the control tick at ``cycle``: the plant's state now, the host's
        estimates, and the tick's setpoints, filtered speeds, signed duties and counts
        (each a (left, right) pair)."""
        wheel, velocity, gyro, ekf, ekf_vel = host.poses()
        speed = plant.s.speed
        # the casters' world headings; ``arrays`` makes them relative to the chassis
        caster = plant.caster_heading
        self._flat.extend((cycle / F_CPU, *plant.pose, *wheel, *velocity, *gyro, setpoint[0], setpoint[1],
                           measured[0], measured[1], speed[0], speed[1], pwm[0], pwm[1], caster[0], caster[1],
                           counts[0], counts[1], *ekf, *ekf_vel, *plant.winding_temps,
                           *plant.battery))
        self.tick_cycles.append(cycle)

    def board(self, row: int, setpoint, measured, pwm, counts) -> None:
        """Rewrites the firmware's columns of ``row`` (the plant's and host's stay as
        ``add`` took them): for a tick whose state was read before the tick had ended."""
        at = row * _LOG_WIDTH
        for name, pair in (("setpoint", setpoint), ("measured", measured), ("pwm", pwm), ("counts", counts)):
            start = at + _LOG_OFFSETS[name]
            self._flat[start:start + 2] = array("d", pair)

    def arrays(self) -> dict[str, np.ndarray]:
        """The columns (``_LOG_COLUMNS``) as arrays, a row per tick (one row of zeros
        without a tick), the casters relative to the chassis, and ``tick_cycles``."""
        names = [name for name, _ in _LOG_COLUMNS]
        out: dict[str, np.ndarray]
        if not self.tick_cycles:
            z3, z2 = np.zeros((1, 3)), np.zeros((1, 2))
            out = {n: z2 for n in names}
            out.update(tick_time=np.zeros(1), truth=z3, odom_wheel=z3, odom_velocity=z3, odom_gyro=z3,
                       odom_ekf=z3, odom_ekf_vel=z3)
        else:
            table = np.frombuffer(self._flat, dtype=np.float64).reshape(len(self.tick_cycles), _LOG_WIDTH)
            out, at = {}, 0
            for name, width in _LOG_COLUMNS:
                out[name] = np.array(table[:, at] if width == 1 else table[:, at:at + width])
                at += width
            # _wrap(heading - chassis heading), the same operations element by element
            relative = out["caster"] - out["truth"][:, 2:3]
            out["caster"] = (relative + math.pi) % (2 * math.pi) - math.pi
        out["tick_cycles"] = np.array(self.tick_cycles, dtype=np.int64)
        return out


class LineLog:
    """The board's TX stream cut into lines, each stamped with the cycle of its last
    byte; keeps the ``EVT:`` and ``BOOT:`` lines."""

    def __init__(self) -> None:
        self._partial = bytearray()
        self.events: list[tuple[float, str]] = []
        self.boots: list[tuple[float, str]] = []
        # every line's time and text, apart: no object per line for the collector (``TickLog``)
        self._times = array("d")
        self._texts: list[str] = []

    @property
    def all(self) -> list[tuple[float, str]]:
        """Every line as (s, text)."""
        return list(zip(self._times, self._texts, strict=True))

    def feed(self, cycle: int, data: bytes) -> None:
        """The board's bytes ``data``, the last one sent at ``cycle``."""
        self._partial += data
        if b"\n" not in data:
            return
        *lines, rest = self._partial.split(b"\n")
        self._partial = rest
        t = cycle / F_CPU
        for raw in lines:
            line = raw.rstrip(b"\r").decode("latin-1")
            self._times.append(t)
            self._texts.append(line)
            if line.startswith("EVT:"):
                self.events.append((round(t, 6), line))
            elif line.startswith("BOOT:"):
                self.boots.append((round(t, 6), line))

    def feed_stamped(self, stamped: list[tuple[int, int]]) -> None:
        """(cycle, byte) pairs, as the simulated Mega logs its TX."""
        start = 0
        for i, (cycle, byte) in enumerate(stamped):
            if byte == 0x0A:
                self.feed(cycle, bytes(b for _, b in stamped[start:i + 1]))
                start = i + 1
        if start < len(stamped):
            self._partial += bytes(b for _, b in stamped[start:])
