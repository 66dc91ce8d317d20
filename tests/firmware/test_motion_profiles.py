"""The trace generator's motion profiles (``hil.profiles.motion_profile``). The random
traces' encoders are scripted, not driven by the duty, so the firmware's rules that
weigh the duty against the wheels' speeds (the grade limit, the motor rule, the
overspeed, the hill hold) fire only where a profile shapes the speeds as the chair would
move. Each profile is drawn, and on a few fixed seeds the firmware reaches each rule,
the port agreeing event by event."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from wcdrive.hil.lockstep import compare, record
from wcdrive.hil.profiles import PROFILES
from wcdrive.hil.traces import FIRST_COMMAND_S, MAX_TRACE_EDGE_RATE, RandomDraw, generate_trace


def _most_edges_in(train_times: np.ndarray, window: float) -> int:
    if train_times.size < 2:
        return int(train_times.size)
    ends = np.searchsorted(train_times, train_times + window, "right")
    return int(np.max(ends - np.arange(train_times.size)))


@pytest.mark.parametrize("duration", [1.5, 5.0])
def test_every_profile_is_generated(duration: float) -> None:
    """Over 200 seeds every profile is drawn, at the fast depth's 1.5 s too (from boot:
    no room for the preamble), and in the longer traces from mid-trace too. A profile's
    writes come in time order, its wheels within the edge-rate cap; a seed whose trace
    has no profile gives the trace it gave before profiles (the profile is the last
    draw)."""
    kinds: Counter[str | None] = Counter()
    starts: Counter[tuple[str, bool]] = Counter()
    for seed in range(200):
        trace = generate_trace(RandomDraw(seed), duration)
        kinds[trace.profile] += 1
        if trace.profile is None:
            old = generate_trace(RandomDraw(seed, profiles=False), duration)
            assert trace.serial == old.serial
            continue
        starts[(trace.profile, trace.profile_start > FIRST_COMMAND_S + 0.1)] += 1
        times = [t for t, _ in trace.serial if t >= trace.profile_start]
        assert times == sorted(times) and min(times, default=1.0) >= FIRST_COMMAND_S
        assert max((t for t, _ in trace.serial), default=0.0) < duration
        for train in trace.encoders.values():
            assert train.times.size == 0 or np.all(np.diff(train.times) >= 0)
            assert _most_edges_in(train.times, 0.002) <= MAX_TRACE_EDGE_RATE * 0.002 + 2
        assert f"profile {trace.profile!r}" in trace.describe()
    assert set(PROFILES) <= set(kinds), kinds
    assert 0.2 < 1 - kinds[None] / 200 < 0.45, kinds
    mid = {kind for kind, later in starts if later}
    assert mid == (set(PROFILES) if duration >= 5.0 else set()), starts


def test_profiles_can_be_left_out() -> None:
    """``RandomDraw(seed, profiles=False)``: the generator as it was before profiles."""
    assert all(generate_trace(RandomDraw(seed, profiles=False), 5.0).profile is None
               for seed in range(60))


# Seeds whose trace (RandomDraw(seed), 2 s long) ends in the profile, from boot, and
# reaches the path (found by trying seeds from 0 up, again since the traces open with a
# neutral command: "Neutral before motion", since ``set:`` draws the drive limits, and
# since it draws tremor_damping):
# what the firmware sends, and the rule behind it.
REACHES = [
    (43, "grade", "STALLED_ON_GRADE"),       # both wheels held back to a crawl
    (52, "overrun", "OVERSPEED"),            # both wheels gaining beyond the setpoint, braked
    (4, "dead_motor", "FAULT,MOTOR_L"),      # one wheel's effort leads, the wheel falls back
    (5, "dead_motor", "FAULT,MOTOR_R"),
    (70, "overrun", "FAULT,MOTOR_L"),        # one wheel gaining while the other brakes and holds
    (15, "parked_drift", "ROLLAWAY"),        # parked, the hold drives the creeping wheels back
]


@pytest.mark.simavr
@pytest.mark.parametrize(("seed", "profile", "event"), REACHES)
def test_the_firmware_reaches_each_path(elf, seed: int, profile: str, event: str) -> None:
    """Each profile leads the firmware onto its rule, the port agreeing throughout; the
    parked drift has the hold drive the wheels back (a duty while holding) before the
    rollaway. A profile that no longer reaches its rule (a threshold moved) needs its
    shape looked at, or another seed."""
    trace = generate_trace(RandomDraw(seed), 2.0)
    assert trace.profile == profile
    recording = record(trace, elf)
    report = compare(recording)
    assert not report.mismatches, "\n".join(
        [str(m) for m in report.mismatches[:10]] + [trace.describe()])
    assert b"EVT:" + event.encode() in recording.tx, (recording.tx.count(b"EVT:"), trace.describe())
    if profile == "parked_drift":
        assert any(e.kind == "tick" and e.after.get("holding") and e.pwm != (0, 0)
                   for e in recording.events)
