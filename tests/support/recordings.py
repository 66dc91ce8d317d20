"""Lock-step recordings for the firmware tests: a trace run on the compiled firmware in
simavr and replayed on the port with no mismatch (``recorded``), its control ticks
(``tick_states``) and the board's lines (``board_lines``, unframed)."""

from __future__ import annotations

from wcdrive.hil.lockstep import Recording, compare, record
from wcdrive.hil.traces import Trace
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
