"""Faults injected into the chair and its wiring, the same way on every backend.

A ``Fault`` is one ``[[fault]]`` entry of a scenario (``wcdrive.sim.scenario``): a
kind, a start time ``at`` (s), an optional ``duration`` (None: to the end), a side for
the kinds that have one and a rate for ``encoder_noise``:

* ``encoder_cut``: the encoder's signals freeze where they are (a cut cable);
* ``encoder_reversed``: its A and B are swapped, so it counts against the motion;
* ``encoder_noise``: channel A chatters at ``rate_hz`` edges/s on top of the real
  signal (a loose connector, EMI);
* ``wheel_locked``: the wheel cannot turn (``Plant.set_wheel_locked``);
* ``motor_dead``: the motor gives no torque, open circuit (``Plant.set_motor_dead``);
* ``brake_open``, ``brake_short``: the parking brake's coil open or shorted
  (``Plant.set_brake_coil``): the brake stays engaged whatever its pin, and its driver's
  status output flags it (an open load while off, an overload while on);
* ``reset``: the board resets at ``at`` (DTR, brown-out);
* ``link_cut``: the host's bytes stop reaching the board from ``at``.

The encoder kinds act on the wire between the encoder and the board: ``EncoderWire``
turns the edge train an ideal encoder makes (``wcdrive.plant.encoders``) into the one
the board's pins see. Both simulated boards use it: ``PlantOnPins`` queues its output on
the simulated Mega's pins; ``PortLoop`` feeds it to the port's interrupt routine. The
plant kinds are applied by ``apply_plant_faults``; ``reset`` and ``link_cut`` are the
boards' and the host's business.

Times on the wire are integers in the board's clock (cycles): ``EncoderWire`` takes
the clock rate, so a step boundary, a fault boundary and an edge never disagree by a
rounding.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from wcdrive.plant.chair import Plant

FAULT_KINDS = ("encoder_cut", "encoder_reversed", "encoder_noise", "wheel_locked", "motor_dead",
               "brake_open", "brake_short", "reset", "link_cut")
#: Kinds that act on an encoder's wire (``EncoderWire``).
ENCODER_KINDS = ("encoder_cut", "encoder_reversed", "encoder_noise")
#: The brake coil's kinds (``Plant.set_brake_coil``: "open", "short").
BRAKE_KINDS = ("brake_open", "brake_short")
#: Kinds that act on the plant (``apply_plant_faults``).
PLANT_KINDS = ("wheel_locked", "motor_dead", *BRAKE_KINDS)
#: Kinds that take a ``side``.
SIDED_KINDS = (*ENCODER_KINDS, "wheel_locked", "motor_dead")
SIDES = ("left", "right")
#: The highest ``rate_hz`` of ``encoder_noise`` (edges/s): one edge per 8 cycles at 16 MHz.
MAX_NOISE_RATE_HZ = 2_000_000.0


@dataclass(frozen=True)
class Fault:
    """One fault (module docstring). ``side`` is "left", "right" or "both" for the
    encoder, wheel and motor kinds and None otherwise; ``duration`` None lasts to the
    end; ``rate_hz`` is the edge rate of ``encoder_noise``. Invalid values raise
    ValueError with a message that names the field."""

    kind: str
    at: float
    side: str | None = None
    duration: float | None = None
    rate_hz: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"kind must be one of {', '.join(FAULT_KINDS)}, not {self.kind!r}")
        if not (isinstance(self.at, (int, float)) and math.isfinite(self.at) and self.at > 0):
            raise ValueError(f"at must be a positive time in seconds, not {self.at!r}")
        if self.kind in SIDED_KINDS:
            if self.side not in ("left", "right", "both"):
                raise ValueError(f"{self.kind} needs side = \"left\", \"right\" or \"both\", "
                                 f"not {self.side!r}")
        elif self.side is not None:
            raise ValueError(f"{self.kind} takes no side")
        if self.duration is not None:
            if self.kind == "reset":
                raise ValueError("reset is instantaneous: it takes no duration")
            if not (isinstance(self.duration, (int, float)) and math.isfinite(self.duration)
                    and self.duration > 0):
                raise ValueError(f"duration must be a positive number of seconds, not {self.duration!r}")
        if self.kind == "encoder_noise":
            if not (isinstance(self.rate_hz, (int, float)) and 0 < self.rate_hz <= MAX_NOISE_RATE_HZ):
                raise ValueError(f"encoder_noise needs rate_hz, edges per second in "
                                 f"(0, {MAX_NOISE_RATE_HZ:.0f}], not {self.rate_hz!r}")
        elif self.rate_hz is not None:
            raise ValueError(f"rate_hz is for encoder_noise only, not {self.kind}")

    @property
    def end(self) -> float:
        """When the fault ends, in s (inf: it lasts to the end)."""
        return math.inf if self.duration is None else self.at + self.duration

    def sides(self) -> tuple[str, ...]:
        """The sides it acts on: one, both, or none (reset, link_cut)."""
        if self.side is None:
            return ()
        return SIDES if self.side == "both" else (self.side,)

    def active_at(self, t: float) -> bool:
        """Whether it acts at time ``t`` (s): ``at <= t < end``."""
        return self.at <= t < self.end

    def cycles(self, clock_hz: float) -> tuple[int, int | None]:
        """Start and end (None: never) in ticks of a ``clock_hz`` clock."""
        start = round(self.at * clock_hz)
        return start, (None if self.duration is None else round(self.end * clock_hz))


def apply_plant_faults(plant: Plant, faults: Iterable[Fault], tick: int, clock_hz: float) -> None:
    """Sets the plant's locked wheels, dead motors and brake coil to what ``faults`` make
    them at ``tick`` of a ``clock_hz`` clock (integer ticks: no rounding decides whether
    a fault at 2.0 s acts on the step that starts at 2.0 s). Of two coil faults at once,
    the later listed counts."""
    locked = {side: False for side in SIDES}
    dead = {side: False for side in SIDES}
    coil: str | None = None
    for f in faults:
        if f.kind not in PLANT_KINDS:
            continue
        start, end = f.cycles(clock_hz)
        if start <= tick and (end is None or tick < end):
            if f.kind in BRAKE_KINDS:
                coil = f.kind.removeprefix("brake_")
            for side in f.sides():
                (locked if f.kind == "wheel_locked" else dead)[side] = True
    if plant.brake_coil != coil:
        plant.set_brake_coil(coil)
    for side in SIDES:
        if plant.wheel_locked(side) != locked[side]:
            plant.set_wheel_locked(side, locked[side])
        if plant.motor_dead(side) != dead[side]:
            plant.set_motor_dead(side, dead[side])


def plant_fault_ticks(faults: Iterable[Fault], clock_hz: float) -> list[int]:
    """The ticks of a ``clock_hz`` clock at which the plant's faults start or end, sorted."""
    ticks: set[int] = set()
    for f in faults:
        if f.kind in PLANT_KINDS:
            start, end = f.cycles(clock_hz)
            ticks.add(start)
            if end is not None:
                ticks.add(end)
    return sorted(ticks)


def swap_ab(states: np.ndarray | int) -> np.ndarray | int:
    """AB states with A and B swapped (``encoder_reversed``)."""
    if isinstance(states, (int, np.integer)):
        s = int(states)
        return ((s & 1) << 1) | (s >> 1)
    arr = np.asarray(states, dtype=np.int64)
    return ((arr & 1) << 1) | (arr >> 1)


@dataclass(frozen=True)
class _Window:
    kind: str
    start: int
    end: int | None          # None: never ends
    period: float = 0.0      # noise: clock ticks between toggles

    def active(self, x: int) -> bool:
        return self.start <= x and (self.end is None or x < self.end)

    def overlaps(self, lo: int, hi: int) -> bool:
        """Acts on some tick of (lo, hi], or ends in it."""
        return self.start <= hi and (self.end is None or self.end > lo)

    def toggles(self, lo: int, hi: int) -> np.ndarray:
        """Noise toggles at ticks in [lo, hi): ``start + floor(j * period)``, j >= 1."""
        if hi <= lo:
            return np.zeros(0, dtype=np.int64)
        j0 = max(1, math.floor((lo - self.start) / self.period) - 1)
        j1 = math.ceil((hi - self.start) / self.period) + 1
        if j1 < j0:
            return np.zeros(0, dtype=np.int64)
        j = np.arange(j0, j1 + 1, dtype=np.int64)
        ticks = self.start + np.floor(j * self.period).astype(np.int64)
        return ticks[(ticks >= lo) & (ticks < hi)]


class EncoderWire:
    """One encoder's wire with the encoder faults on ``side`` among ``faults``, in ticks
    of a ``clock_hz`` clock. ``transform`` turns the ideal encoder's edges over a span
    into the edges on the board's pins; ``state`` is what the pins show now and
    ``true_state`` what the encoder shows (both start at ``state``).

    On the wire: a cut holds the pins at the state they had when it began; a reversal
    swaps A and B; noise toggles A every ``1/rate_hz`` s from ``at`` (on top of the
    rest). When a fault begins or ends the pins take their new state at once, as one
    edge (both channels may change together: the board sees an illegal transition)."""

    def __init__(self, faults: Iterable[Fault], side: str, clock_hz: float, state: int = 0b11) -> None:
        self.side = side
        self.windows: list[_Window] = []
        for f in faults:
            if f.kind in ENCODER_KINDS and side in f.sides():
                start, end = f.cycles(clock_hz)
                period = clock_hz / f.rate_hz if f.rate_hz else 0.0
                self.windows.append(_Window(f.kind, start, end, period))
        self.state = state
        self.true_state = state
        self._held = state
        self._parity = [0] * len(self.windows)

    @property
    def faulty(self) -> bool:
        """Whether any encoder fault is ever on this wire."""
        return bool(self.windows)

    def active(self, lo: int, hi: int) -> bool:
        """Whether a fault acts on some tick of (lo, hi]."""
        return any(w.overlaps(lo, hi) for w in self.windows)

    def faulted_at(self, tick: int) -> bool:
        """Whether a fault acts at ``tick``."""
        return any(w.active(tick) for w in self.windows)

    def ended_by(self, tick: int) -> bool:
        """Whether every fault on the wire has ended at or before ``tick`` (the wire is
        healthy from then on)."""
        return all(w.end is not None and w.end <= tick for w in self.windows)

    def resync(self, state: int) -> None:
        """The encoder shows ``state`` and, no fault acting, so do the pins (a backend
        that left the wire alone while it was healthy calls this before using it again)."""
        self.state = self.true_state = self._held = int(state)

    def _output(self, active: Sequence[bool], true_state: int) -> int:
        cut = reversed_ = False
        parity = 0
        for i, w in enumerate(self.windows):
            if not active[i]:
                continue
            if w.kind == "encoder_cut":
                cut = True
            elif w.kind == "encoder_reversed":
                reversed_ = True
            else:
                parity ^= self._parity[i]
        base = self._held if cut else (int(swap_ab(true_state)) if reversed_ else true_state)
        return base ^ (parity << 1)

    def transform(self, lo: int, hi: int, ticks: np.ndarray, states: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The ideal encoder's edges at ``ticks`` (ascending, in (lo, hi]; ``states`` the
        AB state after each) become the edges on the pins over (lo, hi], returned as
        (ticks, states). ``true_state`` must be the encoder's state at ``lo``."""
        ticks = np.asarray(ticks, dtype=np.int64)
        states = np.asarray(states, dtype=np.int64)
        if not self.active(lo, hi):
            if states.size:
                self.true_state = self.state = int(states[-1])
            return ticks, states
        bounds = sorted({b for w in self.windows for b in (w.start, w.end)
                         if b is not None and lo < b <= hi})
        edges_t: list[np.ndarray] = []
        edges_s: list[np.ndarray] = []
        points = [lo + 1, *bounds, hi + 1]         # segment k: ticks [points[k], points[k+1])
        for k in range(len(points) - 1):
            seg_lo, seg_hi = points[k], points[k + 1]
            if seg_hi <= seg_lo:
                continue
            active = [w.active(seg_lo) for w in self.windows]
            cut_before = any(w.kind == "encoder_cut" and w.active(seg_lo - 1) for w in self.windows)
            if any(a and w.kind == "encoder_cut" for a, w in zip(active, self.windows, strict=True)) \
                    and not cut_before:
                self._held = self.state
            for i, w in enumerate(self.windows):
                if w.kind == "encoder_noise" and not active[i]:
                    self._parity[i] = 0
            if k > 0:
                # A fault boundary: the pins take their new state at once.
                new = self._output(active, self.true_state)
                if new != self.state:
                    edges_t.append(np.array([seg_lo], dtype=np.int64))
                    edges_s.append(np.array([new], dtype=np.int64))
                    self.state = new
            t, s = self._segment(active, seg_lo, seg_hi, ticks, states)
            if t.size:
                edges_t.append(t)
                edges_s.append(s)
        if not edges_t:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return np.concatenate(edges_t), np.concatenate(edges_s)

    def _segment(self, active: list[bool], lo: int, hi: int, ticks: np.ndarray, states: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Edges over the ticks [lo, hi), in which the same faults act."""
        a, b = np.searchsorted(ticks, lo, "left"), np.searchsorted(ticks, hi, "left")
        true_t, true_s = ticks[a:b], states[a:b]
        cut = reversed_ = False
        noise_t: list[np.ndarray] = []
        parity0 = 0
        for i, w in enumerate(self.windows):
            if not active[i]:
                continue
            if w.kind == "encoder_cut":
                cut = True
            elif w.kind == "encoder_reversed":
                reversed_ = True
            else:
                toggles = w.toggles(lo, hi)
                noise_t.append(toggles)
                parity0 ^= self._parity[i]
                self._parity[i] = (self._parity[i] + toggles.size) & 1
        start_true = self.true_state
        if true_s.size:
            self.true_state = int(true_s[-1])
        if not noise_t:
            if cut:
                return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
            out_s = np.asarray(swap_ab(true_s), dtype=np.int64) if reversed_ else true_s
            if out_s.size:
                self.state = int(out_s[-1])
            return true_t, out_s
        toggles = np.sort(np.concatenate(noise_t)) if len(noise_t) > 1 else noise_t[0]
        n_true = true_t.size
        all_t = np.concatenate((true_t, toggles))
        is_noise = np.concatenate((np.zeros(n_true, dtype=bool), np.ones(toggles.size, dtype=bool)))
        order = np.argsort(all_t, kind="stable")
        all_t, is_noise = all_t[order], is_noise[order]
        if cut:
            base = np.full(all_t.size, self._held, dtype=np.int64)
        else:
            index = np.cumsum(~is_noise) - 1                     # the last true edge at or before
            underlying = np.concatenate(([start_true], true_s))[index + 1]
            base = np.asarray(swap_ab(underlying), dtype=np.int64) if reversed_ else underlying
        parity = (parity0 + np.cumsum(is_noise)) & 1
        out = base ^ (parity << 1)
        previous = np.concatenate(([self.state], out[:-1]))
        keep = out != previous
        if out.size:
            self.state = int(out[-1])
        return all_t[keep], out[keep]
