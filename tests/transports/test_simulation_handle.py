"""The typed handle on a simulated board (``wcdrive.boards.simulation.Simulated``),
offered by the simulated ports and every ``PortWrapper`` over them: the floors above
reach the simulation through it only, never a board's attributes."""

from __future__ import annotations

import math
import re
import subprocess
import time
from pathlib import Path

import pytest
import serial

from wcdrive.boards.simulation import GroundTruth, Simulated
from wcdrive.transports.port import simulation_of
from wcdrive.transports.recording import RecordingPort

REPO = Path(__file__).resolve().parents[2]


def _open(url: str) -> serial.SerialBase:
    return serial.serial_for_url(url, timeout=0.2)


def _ran_for(sim: Simulated) -> float:
    """s the board has run: on its own clock, or on the plant's where the board keeps none
    (Eddie's: its ``reported_time`` is always None, and the wait for it ran out)."""
    reported = sim.reported_time
    if reported is not None:
        return reported
    truth = sim.ground_truth()
    return truth.time if truth is not None else 0.0


@pytest.mark.parametrize("url", ["wcsim://?speed=5", "wceddie://?speed=5",
                                 pytest.param("wcavr://?speed=1", marks=pytest.mark.simavr)])
def test_every_simulated_port_offers_the_handle_through_wrappers(url: str) -> None:
    port = _open(url)
    try:
        sim = simulation_of(RecordingPort(RecordingPort(port)))
        assert isinstance(sim, Simulated) and sim is simulation_of(port)
        deadline = time.monotonic() + 5.0
        while _ran_for(sim) < 0.3 and time.monotonic() < deadline:
            time.sleep(0.02)
        truth = sim.ground_truth()
        assert isinstance(truth, GroundTruth)
        assert 0.0 < truth.time and math.isfinite(truth.x) and math.isfinite(truth.heading)
        assert sim.speed > 0
        first = sim.gyro_samples(0)
        if sim.gyro_noise_dps > 0:                   # the chair's boards carry a gyro
            assert first.samples and first.total >= len(first.samples)
            later = sim.gyro_samples(first.total)
            assert all(t > first.samples[-1][0] for t, _ in later.samples)
        else:
            assert not first.samples
    finally:
        port.close()
    assert simulation_of(port) is None                # a closed port has none


def test_a_device_like_port_has_no_simulation(tmp_path: Path) -> None:
    port = serial.serial_for_url("loop://", timeout=0.1)
    assert simulation_of(port) is None and simulation_of(RecordingPort(port)) is None


def test_nothing_above_the_boards_reaches_into_a_board() -> None:
    """No ``_pins``, no board lock, no ``getattr(port, "board")`` outside wcdrive/boards/."""
    files = subprocess.run(["git", "ls-files", "wcdrive"], cwd=REPO, capture_output=True, text=True,
                           check=True).stdout.split()
    pattern = re.compile(r"\b_pins\b|board\._lock|getattr\((?:port|self\.port), \"board\"")
    above = [p for p in files if p.endswith(".py") and not p.startswith("wcdrive/boards/")]
    found = [f"{path}:{n}" for path in above
             for n, line in enumerate((REPO / path).read_text().splitlines(), 1) if pattern.search(line)]
    assert not found, found
