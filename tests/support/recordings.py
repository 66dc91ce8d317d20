"""Lock-step recordings for the firmware tests: a trace run on the compiled firmware in
simavr and replayed on the port with no mismatch (``recorded``), its control ticks
(``tick_states``) and the board's lines (``board_lines``, unframed); and the pieces the
traces are made of: a command repeated (``every``), a wheel turning steadily
(``turning``), an encoder's channel A chattering (``chatter``)."""

from __future__ import annotations

import numpy as np

from wcdrive.hil.lockstep import Recording, compare, record
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory
from wcdrive.protocol.codec import board_unframe


def recorded(trace: Trace) -> Recording:
    """``trace`` on the firmware in simavr, held to the port: 0 mismatches."""
    recording = record(trace)
    report = compare(recording)
    assert report.mismatches == [], "\n".join(str(m) for m in report.mismatches[:10])
    return recording


def tick_states(recording: Recording) -> list[tuple[float, dict]]:
    """(its millis() in s, the globals after it) of each control tick."""
    return [(ev.arg / 1000.0, ev.after) for ev in recording.events if ev.kind == "tick"]


def board_lines(recording: Recording, prefix: bytes) -> list[bytes]:
    """The board's lines that start with ``prefix``, a v4 frame's text without its frame."""
    out = []
    for line in recording.tx.split(b"\r\n"):
        unframed = board_unframe(line)
        text = line if unframed is None else unframed[0]
        if text.startswith(prefix):
            out.append(text)
    return out


#: Encoder counts per radian of wheel (``CPR``, 10,000 a turn).
COUNTS_PER_RAD = 10000 / (2 * np.pi)


def every(command: bytes, t0: float, t1: float, period: float = 0.1) -> list[tuple[float, bytes]]:
    """``command`` written every ``period`` s from ``t0`` to before ``t1``."""
    return [(round(float(t), 4), command) for t in np.arange(t0, t1, period)]


def turning(until: float, mirrored: bool, speed: float) -> EdgeTrain:
    """A wheel at rest until 0.3 s, then at ``speed`` rad/s (the left one counts backwards)."""
    t = np.linspace(0.0, until, 4000)
    angle = np.where(t < 0.3, 0.0, (t - 0.3) * speed)
    return edges_from_trajectory(t, 0.5 + (-1 if mirrored else 1) * angle * COUNTS_PER_RAD)


def chatter(t0: float, duration: float, rate: float) -> EdgeTrain:
    """Channel A of an encoder toggling ``rate`` times a second (a loose connector)."""
    n = int(duration * rate)
    times = t0 + np.arange(n) / rate
    states = np.where(np.arange(n) % 2 == 0, 0b01, 0b11).astype(np.uint8)
    return EdgeTrain(times, states, 0, 0)
