"""Neutral before motion (ISO 7176-14, "control signal at switch-on"; docs/safety.md):
after a boot, an e-stop or fault reset, a watchdog stop and a PPM loss the board drives
only once a neutral (zero) command has stood ``NEUTRAL_TICKS`` ticks with no motion
command after it. A motion command before that is refused (``ERR:neutral``, or
``NAK:neutral`` for a frame) with ``EVT:NOT_NEUTRAL`` once; ``EVT:NEUTRAL`` when the
neutral is then confirmed; ``NEUTRAL_FAULT_TICKS`` ticks (5 s) of refusal without a
neutral command is ``EVT:DEFLECTED``, until neutral. The TLM line's ``state`` field
says both (bits 0 and 1).

Every trace runs on the compiled firmware in simavr and is replayed on the port in lock
step (``wcdrive.hil.lockstep``: 0 mismatches), so each behaviour holds on both. The
encoders stand still: what is watched is what the firmware drives (PWM, targets), and
a drive is watched only in its first ticks (standing encoders under a growing duty are
a stall fault a few ticks later). tests/sim/test_neutral_plant.py watches the chair.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.recordings import board_lines, recorded, tick_states
from wcdrive.firmware import constants as C
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.plant.encoders import edges_from_trajectory
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line

pytestmark = pytest.mark.simavr

STILL = edges_from_trajectory(np.array([0.0, 10.0]), np.array([0.5, 0.5]))
FORWARD = b"x:0.500,t:0.000,"
NEUTRAL = b"x:0.000,t:0.000,"


def _every(command: bytes, t0: float, t1: float, period: float = 0.05) -> list[tuple[float, bytes]]:
    return [(round(float(t), 4), command) for t in np.arange(t0, t1, period)]


def _run(serial: list[tuple[float, bytes]], duration: float) -> Recording:
    return recorded(Trace(duration=duration, serial=sorted(serial, key=lambda w: w[0]),
                          encoders={"left": STILL, "right": STILL}))


def _driven(ticks: list[tuple[float, dict]], t0: float, t1: float) -> bool:
    """Whether any tick in [t0, t1) drove a motor or had a target."""
    return any(after["pwmL"] or after["pwmR"] or after["targetL"] or after["targetR"]
               for t, after in ticks if t0 <= t < t1)


@pytest.mark.parametrize("command", [
    FORWARD,                                          # CMDVEL, the guide's host
    b"rp05.00,lp05.00,",                              # WHEEL, a ros2_control plugin
    b"ppm:1500,1800,1500,1500,1500,1500,1500,1500,",   # PPM: the stick forward at switch-on
], ids=["cmdvel", "wheel", "ppm"])
def test_a_command_streamed_from_switch_on_moves_nothing_until_neutral(command: bytes) -> None:
    """The host streams its command from the boot (as one does that kept streaming across
    a reset): refused, the motors unpowered, for 1 s; a neutral command, and the same
    stream drives from NEUTRAL_TICKS ticks after it."""
    neutral = b"ppm:1500,1500,1500,1500,1500,1500,1500,1500," if command.startswith(b"ppm") else NEUTRAL
    rec = _run([*_every(command + b"\n", 0.01, 1.0), (1.0, neutral + b"\n"),
                *_every(command + b"\n", 1.2, 2.0)], 2.2)
    ticks = tick_states(rec)
    assert not _driven(ticks, 0.0, 1.05)
    assert _driven(ticks, 1.2, 1.35)
    errors = board_lines(rec, b"ERR:")
    refused = errors[:errors.index(b"ERR:fault")] if b"ERR:fault" in errors else errors
    assert len(refused) >= 15 and set(refused) == {b"ERR:neutral"}
    assert board_lines(rec, b"EVT:NOT_NEUTRAL") == [b"EVT:NOT_NEUTRAL"]          # once a wait
    assert board_lines(rec, b"EVT:NEUTRAL") == [b"EVT:NEUTRAL"]
    waited = [after["needNeutral"] for t, after in ticks]
    assert waited[0] == 1 and waited[-1] == 0


def test_a_framed_command_is_refused_with_a_nak_and_the_state_is_in_tlm() -> None:
    """After ``hello:4`` every line is framed: the refusal is ``NAK:<seq>,neutral`` and
    TLM's last field is the state (1: waiting; 0 once neutral stood)."""
    writes = [(0.01, frame(b"hello:4", 1))]
    writes += [(t, frame(FORWARD, 2 + i)) for i, (t, _) in enumerate(_every(b"", 0.1, 0.5))]
    writes += [(0.5, frame(NEUTRAL, 40)), (0.7, frame(FORWARD, 41))]
    rec = _run(writes, 1.0)
    text = rec.tx.decode(errors="replace")
    naks = [line for line in text.split("\r\n") if line.startswith("NAK:")]
    assert naks and all(",neutral#" in line for line in naks), naks     # NAK:<seq>,neutral, framed
    states = [int(line.split(":", 1)[1].split("#")[0].split(",")[16])
              for line in text.split("\r\n") if "TLM:" in line]
    assert states[0] == 1 and states[-1] == 0 and 1 in states[:5]
    assert _driven(tick_states(rec), 0.75, 1.0)


def test_a_motion_command_inside_the_hold_restarts_it() -> None:
    """A neutral command, a motion command 30 ms later (refused: the neutral had not
    stood NEUTRAL_TICKS ticks), and the wait starts over."""
    rec = _run([(0.01, NEUTRAL + b"\n"), (0.04, FORWARD + b"\n"), (0.3, FORWARD + b"\n"),
                (0.5, NEUTRAL + b"\n"), (0.7, FORWARD + b"\n")], 1.0)
    ticks = tick_states(rec)
    assert not _driven(ticks, 0.0, 0.55)
    assert _driven(ticks, 0.7, 0.85)
    assert board_lines(rec, b"ERR:")[:2] == [b"ERR:neutral", b"ERR:neutral"]


@pytest.mark.parametrize("cause", ["watchdog", "estop_reset", "ppm_lost"])
def test_after_a_stop_the_board_needs_neutral_again(cause: str) -> None:
    """Neutral, a motion command taken; then a watchdog stop (the link silent while it
    drives), or a stop and an e-stop and its reset, or a stop and a PPM frame that says
    the transmitter is lost: the host's motion command, resumed as it was, is refused
    until a neutral command."""
    ppm = cause == "ppm_lost"
    go = b"ppm:1500,1800,1500,1500,1500,1500,1500,1500,\n" if ppm else FORWARD + b"\n"
    stop = b"ppm:1500,1500,1500,1500,1500,1500,1500,1500,\n" if ppm else NEUTRAL + b"\n"
    writes = [(0.01, stop), (0.3, go), (0.4, stop)]
    if cause == "watchdog":     # the link lost while the command drives: watchdog_ms 100
        writes = [(0.005, b"set:watchdog_ms=100\n"), (0.01, stop), (0.3, go)]
        resume = 1.0
    elif cause == "estop_reset":
        writes += [(0.5, b"estop\n"), (1.0, b"reset\n")]
        resume = 1.05
    else:
        writes += [(0.5, b"ppm:1500,0800,1500,1500,1500,1500,1500,1500,\n")]
        resume = 0.55
    writes += [*_every(go, resume, resume + 0.6), (resume + 0.6, stop), (resume + 0.8, go)]
    rec = _run(writes, resume + 1.0)
    ticks = tick_states(rec)
    assert _driven(ticks, 0.32, 0.39)
    assert not _driven(ticks, resume, resume + 0.65)
    assert _driven(ticks, resume + 0.8, resume + 0.95)
    assert board_lines(rec, b"EVT:NOT_NEUTRAL") == [b"EVT:NOT_NEUTRAL"]
    assert set(board_lines(rec, b"ERR:")) == {b"ERR:neutral"}


def test_five_seconds_without_neutral_is_the_neutral_fault_until_neutral() -> None:
    """A control held deflected from switch-on: EVT:DEFLECTED NEUTRAL_FAULT_TICKS
    ticks (5 s) after the first refusal, the state's bit 1 set; a neutral command clears
    it and the chair drives."""
    rec = _run([*_every(FORWARD + b"\n", 0.01, 5.6, 0.1), (5.6, NEUTRAL + b"\n"),
                (5.8, FORWARD + b"\n")], 6.0)
    ticks = tick_states(rec)
    faulted = [t for t, after in ticks if after["neutralFault"]]
    assert faulted and 5.0 <= faulted[0] <= 5.1 + C.CONTROL_PERIOD_MS / 1000
    assert board_lines(rec, b"EVT:DEFLECTED") == [b"EVT:DEFLECTED"]
    assert not _driven(ticks, 0.0, 5.65)
    assert ticks[-1][1]["neutralFault"] == 0 and _driven(ticks, 5.8, 5.95)


def test_the_seed_era_hosts_zero_first_then_drive() -> None:
    """The ros2_control plugin's opening: ``rp0.0,lp0.0,`` and a line end, 2 s, then its
    commands at 100 Hz with no line end: it drives, nothing refused."""
    writes = [(0.01, b"rp0.0,lp0.0,\n"), *_every(b"rp03.00,lp03.00,", 2.0, 2.1, 0.01)]
    rec = _run(writes, 2.2)
    assert board_lines(rec, b"ERR:") == [] and board_lines(rec, b"EVT:NOT_NEUTRAL") == []
    assert _driven(tick_states(rec), 2.0, 2.15)


def test_the_neutral_fault_is_tlm_state_bit_1_for_a_framed_host() -> None:
    """A v4 host (``hello:4``, its commands framed) holding the control deflected from
    switch-on: TLM's state has bit 0 (waiting for neutral) from the first refusal, and
    bit 1 (the neutral fault) from ``EVT:DEFLECTED`` until a neutral command."""
    writes = [*_every(FORWARD, 0.05, 5.6, 0.1), (5.6, NEUTRAL), (5.8, FORWARD)]
    serial = [(0.01, b"hello:4\n")] + [(t, frame(cmd, k + 1)) for k, (t, cmd) in enumerate(writes)]
    rec = _run(serial, 6.0)
    assert board_lines(rec, b"EVT:DEFLECTED") == [b"EVT:DEFLECTED"]
    states = [m for m in map(parse_line, board_lines(rec, b"TLM:")) if isinstance(m, ExtendedTelemetry)]
    assert len(states) > 100
    faulted = [k for k, m in enumerate(states) if m.neutral_fault]
    assert faulted and all(states[k].needs_neutral for k in faulted)
    assert faulted == list(range(faulted[0], faulted[-1] + 1))      # one run, then cleared
    assert 95 <= faulted[0] <= 103 and not states[-1].neutral_fault and not states[-1].needs_neutral
