"""Fault detection, run on the compiled firmware in simavr and replayed on the port in
lock step (``wcdrive.hil.lockstep``: every controller value after every firmware event
and the whole TX stream compared, 0 mismatches), so each test covers both backends.

The traces drive the board open loop (the encoders do what the test says, whatever the
motors do), which is exactly the wiring fault each test stands for. The closed-loop
versions, with the chair on the pins and its ground truth, are the bundled fault
scenarios (tests/sim/test_fault_injection.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware
from wcdrive.hil.lockstep import Recording, compare, record
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import EdgeTrain, edges_from_trajectory
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line

pytestmark = pytest.mark.simavr

COUNTS_PER_RAD = 10000 / (2 * math.pi)


def _wheel(rad_s: float, t0: float, t1: float, mirrored: bool = False) -> EdgeTrain:
    """The edges of a wheel turning at ``rad_s`` from ``t0`` to ``t1`` (the left wheel
    is mounted mirrored: its counts run backwards)."""
    rate = rad_s * COUNTS_PER_RAD * (-1 if mirrored else 1)
    return edges_from_trajectory(np.array([0.0, t0, t1]), np.array([0.5, 0.5, 0.5 + rate * (t1 - t0)]))


def _commands(command: bytes, t0: float, t1: float, period: float = 0.1) -> list[tuple[float, bytes]]:
    """``command`` every ``period`` s from ``t0``, after a neutral command at 10 ms (the
    board drives only once one stood: docs/safety.md, "Neutral before motion"); ``t0``
    at least ``T0``."""
    return [(0.01, NEUTRAL), *((t, command) for t in np.arange(t0, t1, period))]


#: When the traces' drives start: their neutral command has stood by then.
T0 = 0.17
NEUTRAL = b"rp0,lp0,\n"


def _run(trace: Trace) -> tuple[Recording, bytes]:
    recording = record(trace)
    report = compare(recording)
    assert report.mismatches == [], "\n".join(str(m) for m in report.mismatches[:10])
    return recording, recording.tx


def _events(tx: bytes) -> list[bytes]:
    """The EVT lines, but the boot's EVT:PARAMS_* (the EEPROM parameters)."""
    lines = tx.split(b"\r\n")
    return [line for line in lines if line.startswith(b"EVT:") and not line.startswith(b"EVT:PARAMS")]


def _fault_tick(recording: Recording) -> tuple[int, float]:
    """The first tick that latched a fault: (its faultFlags, its time in s)."""
    for ev in recording.events:
        if ev.kind == "tick" and ev.after.get("faultFlags"):
            return int(ev.after["faultFlags"]), ev.cycle / 16e6
    raise AssertionError("no fault latched")


def test_a_wheel_driven_without_counts_latches_a_stall_and_parks() -> None:
    """Left encoder cut (no edges) while the right wheel turns: ENC_STALL_L within
    FAULT_STALL_TICKS ticks of the duty reaching FAULT_STALL_PWM; the left motor at
    duty 0, the right one, still turning, braked by its PID (not parked), the brake
    engaged."""
    trace = Trace(duration=1.65, serial=_commands(b"rp3.0,lp3.0,", T0, 1.65),
                  encoders={"right": _wheel(3.0, T0, 1.65)})
    recording, tx = _run(trace)
    assert _events(tx) == [b"EVT:FAULT,ENC_STALL_L"]
    faults, _ = _fault_tick(recording)
    assert faults == 0x01
    last = recording.events[-1].after
    assert last["parked"] == 0 and last["brakeReleased"] == 0
    assert recording.events[-1].pwm[0] == 0 and last["pwmR"] > 0 and last["dirR"] == C.LOW
    assert last["faultFlags"] == 0x01 and last["targetR"] == 0.0
    # Commands after the fault are refused: ERR:fault, counted.
    assert tx.count(b"ERR:fault\r\n") >= 3


def test_the_stall_is_caught_before_the_duty_runs_away() -> None:
    """The duty of the stalled wheel never winds up past what it had when the counts
    stopped plus one PID step: a suspect tick holds the output."""
    trace = Trace(duration=1.15, serial=_commands(b"rp3.0,lp3.0,", T0, 1.15),
                  encoders={"left": _wheel(3.0, T0, 0.55, mirrored=True),
                            "right": _wheel(3.0, T0, 1.15)})
    recording, tx = _run(trace)
    assert _events(tx) == [b"EVT:FAULT,ENC_STALL_L"]
    _, at = _fault_tick(recording)
    assert at - 0.55 <= (C.FAULT_STALL_TICKS + 1) * 0.05 + 0.005
    duties = [ev.pwm[0] for ev in recording.events if ev.kind == "tick"]
    assert max(duties) <= 2.55 * 100 * 0.45, duties      # never near full power


def test_both_wheels_driven_without_counts_is_driver_dead() -> None:
    trace = Trace(duration=1.65, serial=_commands(b"x:0.5,t:0,", T0, 1.65))
    recording, tx = _run(trace)
    assert _events(tx) == [b"EVT:FAULT,DRIVER_DEAD"]
    assert _fault_tick(recording)[0] == 0x40


def test_counts_against_the_setpoint_latch_a_reversed_encoder() -> None:
    """Right encoder wired A/B swapped: it counts backwards while the wheel is driven
    forward. ENC_REVERSED_R after FAULT_REVERSE_TICKS ticks beyond FAULT_REVERSE_SPEED."""
    trace = Trace(duration=1.65, serial=_commands(b"rp3.0,lp3.0,", T0, 1.65),
                  encoders={"left": _wheel(3.0, T0, 1.65, mirrored=True),
                            "right": _wheel(-3.0, T0, 1.65)})
    recording, tx = _run(trace)
    assert _events(tx) == [b"EVT:FAULT,ENC_REVERSED_R"]
    faults, at = _fault_tick(recording)
    assert faults == 0x08
    # The setpoint passes 1 rad/s after 0.2 s (5 rad/s^2); three ticks later at most.
    assert at <= T0 + 1.0 / 5.0 + (C.FAULT_REVERSE_TICKS + 1) * 0.05 + 0.01


def test_illegal_transitions_latch_an_implausible_encoder() -> None:
    """FAULT_ILLEGAL_PER_TICK transitions with both channels changing in one tick."""
    t = 0.3 + np.arange(2 * C.FAULT_ILLEGAL_PER_TICK) * 1e-3
    states = np.tile([0b00, 0b11], C.FAULT_ILLEGAL_PER_TICK)
    trace = Trace(duration=0.6, encoders={"left": EdgeTrain(t, states, 0, 0)})
    recording, tx = _run(trace)
    assert _events(tx) == [b"EVT:FAULT,ENC_IMPLAUSIBLE_L"]
    assert _fault_tick(recording)[0] == 0x10


def _chatter(rate_hz: float, t0: float, t1: float, start_state: int = 0b11) -> EdgeTrain:
    """Channel A toggling at ``rate_hz`` edges/s (B still): a loose connector."""
    times = np.arange(t0, t1, 1.0 / rate_hz)
    states = np.where(np.arange(times.size) % 2 == 0, start_state ^ 0b10, start_state)
    return EdgeTrain(times, states.astype(np.int64), 0, 0)


@pytest.mark.parametrize("rate_hz", [100_000, 500_000])
def test_an_edge_storm_is_masked_within_one_window_and_never_stalls_the_ticks(rate_hz: float) -> None:
    """A chattering channel on both encoders: each ISR masks its encoder at its
    STORM_EDGES-th edge within a 1.024 ms window, the ticks keep their 50 ms grid and the
    fault is latched (ENC_IMPLAUSIBLE on both wheels, one EVT line each)."""
    storm = (0.2, 0.5)
    trace = Trace(duration=0.8, serial=_commands(b"x:0.0,t:0,", 0.02, 0.8),
                  encoders={"left": _chatter(rate_hz, *storm), "right": _chatter(rate_hz, *storm)})
    recording, tx = _run(trace)
    assert _events(tx) == [b"EVT:FAULT,ENC_IMPLAUSIBLE_L", b"EVT:FAULT,ENC_IMPLAUSIBLE_R"]
    ticks = [ev.cycle for ev in recording.events if ev.kind == "tick"]
    gaps_ms = np.diff(ticks) / 16e3
    assert gaps_ms.max() <= 53.0, gaps_ms.max()
    _, at = _fault_tick(recording)
    assert at <= storm[0] + 0.055


def test_reset_releases_a_fault_once_parked_and_motion_resumes() -> None:
    """After a stall fault, framed motion is NAKed with "fault", a stop is accepted, and
    ``reset`` (parked: at once) releases it; the TLM line carries flag bit 7 and the
    fault bits while latched."""
    serial = [(0.02, frame(b"hello", 1)), (0.04, frame(b"x:0,t:0,", 40))]     # and neutral first
    serial += [(t, frame(b"rp3.0,lp3.0,", 2 + k)) for k, t in enumerate(np.arange(0.25, 0.95, 0.1))]
    serial += [(1.0, frame(b"rp1.0,lp1.0,", 50)), (1.05, frame(b"x:0,t:0,", 51)),
               (1.1, frame(b"reset", 52)), (1.25, frame(b"x:0,t:0,", 53))]
    trace = Trace(duration=1.45, serial=serial)
    recording, tx = _run(trace)
    lines = tx.split(b"\r\n")
    assert b"NAK:50,fault" in lines and b"ACK:51" in lines and b"ACK:52" in lines
    tlm = [parse_line(line) for line in lines if line.startswith(b"TLM:")]
    latched = [m for m in tlm if isinstance(m, ExtendedTelemetry) and m.fault_latched]
    assert latched and all(m.fault_names == ("DRIVER_DEAD",) for m in latched)
    assert recording.events[-1].after["faultFlags"] == 0


def test_no_fault_while_parked_with_idle_encoders() -> None:
    """A board at rest with idle encoders never trips: the port alone, 60 s of ticks."""
    fw = Firmware()
    now = fw.state.lastControlTime
    out = b""
    for _ in range(1200):
        now += 50
        out += fw.tick(now, 0, 0)
    assert b"EVT:" not in out and fw.state.faultFlags == 0


