"""``reset`` and the storm guard (docs/safety.md, "Encoder storms"): ``reset`` unmasks
only an encoder whose storm a control tick has latched as a fault, the fault it clears.
A storm that masks an encoder between a tick and a reset stays masked, and the next tick
latches its fault: the storm, and the edges lost while it was masked, are reported, not
swallowed. Both backends, in lock step."""

from __future__ import annotations

import pytest

from tests.support.recordings import chatter, recorded, tick_states
from wcdrive.hil.traces import Trace

pytestmark = pytest.mark.simavr


def _storm_and_reset(reset_at: float):
    return recorded(Trace(duration=0.4, serial=[(reset_at, b"reset\n")],
                          encoders={"right": chatter(0.105, 0.0025, 100_000)}))


def test_a_storm_masked_before_a_reset_is_latched_at_the_next_tick() -> None:
    """A 2.5 ms storm at 100,000 edges/s on the right encoder from 0.105 s, just after a
    tick: the guard masks it within the first Timer0 period. At 0.125 s the host says
    ``reset`` before any tick has seen the storm: the encoder stays masked and the tick
    after (0.15 s) latches ENC_IMPLAUSIBLE_R. Red with ``reset`` unmasking at once: no
    tick sees a storm and no fault is reported."""
    rec = _storm_and_reset(0.125)
    assert b"EVT:FAULT,ENC_IMPLAUSIBLE_R\r\n" in rec.tx
    latched = [t for t, after in tick_states(rec) if after["stormTickR"]]
    assert latched and 0.125 < latched[0] < 0.2
    assert all(after["stormTickR"] for t, after in tick_states(rec) if t > latched[0])


def test_a_reset_after_the_tick_latched_the_storm_unmasks_it() -> None:
    """The same storm, ``reset`` at 0.16 s, after the 0.15 s tick latched its fault (the
    chair at rest, parked): the reset clears the fault and unmasks the encoder, which
    counts again."""
    rec = _storm_and_reset(0.160)
    assert b"EVT:FAULT,ENC_IMPLAUSIBLE_R\r\n" in rec.tx
    states = tick_states(rec)
    assert any(after["stormTickR"] for t, after in states if t < 0.16)
    assert not any(after["stormTickR"] or after["faultFlags"] for t, after in states if t > 0.17)
