"""The README's first command, as a new user types it: ``wcdrive sim square`` prints
ground truth against odometry and writes its PNG plots to ``wcdrive-out/`` (in the
directory it runs in)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

PNG = b"\x89PNG\r\n\x1a\n"


def test_wcdrive_sim_square_prints_truth_against_odometry_and_writes_its_plots(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "wcdrive", "sim", "square"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    out = result.stdout
    assert out.startswith("scenario square (port):")
    truth = re.search(r"^\s+ground truth\s+(-?[\d.]+)\s+(-?[\d.]+)\s+(-?[\d.]+)", out, re.M)
    odometry = re.search(r"^\s+wheel odometry \(position\)\s+(-?[\d.]+)\s+(-?[\d.]+)\s+(-?[\d.]+)\s+([\d.]+)",
                         out, re.M)
    assert truth and odometry, out
    # the square closes near its start, and the odometry's error is what the table says
    assert abs(float(truth[1])) < 0.1 and abs(float(truth[2])) < 0.3
    assert float(odometry[4]) < 0.01
    plots = sorted((tmp_path / "wcdrive-out" / "square").glob("*.png"))
    assert [p.name for p in plots] == ["pwm.png", "trajectory.png", "wheels.png"]
    for p in plots:
        data = p.read_bytes()
        assert data.startswith(PNG) and len(data) > 10_000, p
    assert "plots: wcdrive-out/square/trajectory.png" in out
