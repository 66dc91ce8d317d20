"""Hypothesis strategies for the chair's inputs, the generators the project's own
property and differential tests use (``tests/firmware/test_differential.py`` draws its traces
from ``traces()``).

Each strategy wraps a generator that takes a source of choices (``wcdrive.hil.traces``:
``RandomDraw`` for seeded runs such as ``wcdrive verify``, ``HypothesisDraw`` here, so
hypothesis can shrink a failing example):

- ``commands()``: one command line as the host would write it (bytes): CMDVEL, WHEEL,
  PPM, stops, get/set of every parameter, hello, estop and reset, malformed ones, some
  as v3 frames with good or damaged CRCs.
- ``byte_streams()``: several commands glued with terminators (or none), as one bytes
  object: what a serial port may deliver in one read.
- ``encoder_traces(duration)``: a quadrature edge train (``EdgeTrain``) of one wheel:
  speeds up to 40,000 edges/s, reversals, pauses, illegal transitions.
- ``traces(duration)``: a whole input trace for the firmware (``Trace``): timed
  serial writes and both encoders.
- ``faults(duration)``: one ``Fault`` of any kind (a scenario's ``[[fault]]``).
- ``scenarios()``: a short ``Scenario`` of random segments, with faults or not.
- ``envelope_drives(cases)``: one drive of the chair's operating envelope
  (``wcdrive.testing.envelope.Drive``: grades, ramp bands and their transitions,
  kerb cuts beyond it, loads, speeds, turns, gains, host rates); ``Drive.toml()`` is
  its scenario file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any, TypeVar

from hypothesis import strategies as st

from wcdrive.hil.traces import (
    Draw,
    HypothesisDraw,
    Trace,
    command,
    encoder_motion,
    generate_trace,
    terminator,
)
from wcdrive.plant.encoders import EdgeTrain
from wcdrive.plant.faults import FAULT_KINDS, SIDED_KINDS, Fault
from wcdrive.sim.scenario import Scenario, Segment
from wcdrive.testing.envelope import BEYOND, INSIDE, Drive, drive

T = TypeVar("T")

__all__ = ["byte_streams", "commands", "encoder_traces", "envelope_drives", "fault", "faults", "scenario",
           "scenarios", "traces"]


def _strategy(generator: Callable[..., T], *args: Any) -> st.SearchStrategy[T]:
    """``generator(draw, *args)`` as a strategy whose choices hypothesis shrinks."""

    @st.composite
    def build(draw_fn: Callable[..., Any]) -> T:
        return generator(HypothesisDraw(SimpleNamespace(draw=draw_fn)), *args)

    return build()


# ---- generators on any Draw (RandomDraw for seeded runs) -------------------------------
def _command(draw: Draw) -> bytes:
    return command(draw, [draw.choice([-1, 1])], [draw.boolean(0.3)]) + terminator(draw)


def _byte_stream(draw: Draw, max_commands: int) -> bytes:
    sign, hello = [1], [False]
    return b"".join(command(draw, sign, hello) + terminator(draw)
                    for _ in range(draw.integer(1, max_commands)))


def fault(draw: Draw, duration: float = 10.0) -> Fault:
    """One fault of any kind (``FAULT_KINDS``) starting within the first 80 % of
    ``duration`` s."""
    kind = draw.choice(FAULT_KINDS)
    at = round(draw.real(0.2, max(0.3, 0.8 * duration)), 3)
    side = draw.choice(["left", "right", "both"]) if kind in SIDED_KINDS else None
    length = None
    if kind != "reset" and draw.boolean(0.5):
        length = round(draw.real(0.05, 2.0), 3)
    rate = round(draw.real(1_000.0, 500_000.0), 1) if kind == "encoder_noise" else None
    return Fault(kind=kind, at=at, side=side, duration=length, rate_hz=rate)


def scenario(draw: Draw, max_segments: int = 4, with_faults: bool | None = None) -> Scenario:
    """A scenario of 1 to ``max_segments`` segments of 0.2 to 2 s (CMDVEL, WHEEL,
    stop, silence) and 0 to 2 faults (``with_faults`` None: either)."""
    segments = []
    for _ in range(draw.integer(1, max_segments)):
        kind = draw.choice(["cmdvel", "cmdvel", "wheel", "stop", "silence"])
        length = round(draw.real(0.2, 2.0), 3)
        values: tuple[float, ...] = ()
        if kind == "cmdvel":
            values = (round(draw.real(-1.0, 1.0), 3), round(draw.real(-1.5, 1.5), 3))
        elif kind == "wheel":
            values = (round(draw.real(-8.0, 8.0), 3), round(draw.real(-8.0, 8.0), 3))
        segments.append(Segment(kind=kind, values=values, duration=length))
    sc = Scenario(name="generated", description="drawn by wcdrive.testing.strategies",
                  segments=tuple(segments), settle_s=0.5)
    wanted = draw.boolean(0.5) if with_faults is None else with_faults
    if wanted:
        sc = dataclasses.replace(sc, faults=tuple(fault(draw, sc.duration)
                                                  for _ in range(draw.integer(1, 2))))
    return sc


# ---- the strategies ------------------------------------------------------------------
def commands() -> st.SearchStrategy[bytes]:
    """One host command line (bytes), valid or not, framed or not."""
    return _strategy(_command)


def byte_streams(max_commands: int = 8) -> st.SearchStrategy[bytes]:
    """Up to ``max_commands`` commands run together with their terminators."""
    return _strategy(_byte_stream, max_commands)


def encoder_traces(duration: float = 2.0) -> st.SearchStrategy[EdgeTrain]:
    """One wheel's encoder edge train over ``duration`` s."""
    return _strategy(encoder_motion, duration)


def traces(duration: float = 2.0) -> st.SearchStrategy[Trace]:
    """A whole firmware input trace of ``duration`` s (``wcdrive.hil.traces.Trace``)."""
    return _strategy(generate_trace, duration)


def faults(duration: float = 10.0) -> st.SearchStrategy[Fault]:
    """One ``Fault`` within a run of ``duration`` s."""
    return _strategy(fault, duration)


def scenarios(max_segments: int = 4, with_faults: bool | None = None) -> st.SearchStrategy[Scenario]:
    """A short ``Scenario`` to run with ``wcdrive.sim.runner.run``."""
    return _strategy(scenario, max_segments, with_faults)


def envelope_drives(cases: tuple[str, ...] = INSIDE + BEYOND) -> st.SearchStrategy[Drive]:
    """One healthy drive of the operating envelope, of a class in ``cases``
    (``wcdrive.testing.envelope``: ``INSIDE``, ``BEYOND``); it shrinks toward the
    first class, the level, the slowest speed, no turn, 10 Hz and the default gains."""
    return _strategy(drive, cases)
