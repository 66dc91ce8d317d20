"""The drive profiles with the plant (docs/safety.md, "Drive profiles"): the ISO
7176-6-style figures of ``benchmarks/drive_profiles.py`` on the port, each profile of the
board's table selected by number and held to its own limits, and the open profile to
what the chair did before them."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "drive_profiles.py"
_spec = importlib.util.spec_from_file_location("drive_profiles", _PATH)
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
sys.modules["drive_profiles"] = bench
_spec.loader.exec_module(bench)


@pytest.mark.parametrize(("name", "backend"), [
    ("indoor", "port"), pytest.param("outdoor", "port", marks=pytest.mark.thorough), ("attendant", "port"),
    pytest.param("indoor", "simavr", marks=[pytest.mark.simavr, pytest.mark.thorough]),
    pytest.param("outdoor", "simavr", marks=[pytest.mark.simavr, pytest.mark.thorough]),
    pytest.param("attendant", "simavr", marks=[pytest.mark.simavr, pytest.mark.thorough])])
def test_each_figure_keeps_within_its_profile(name: str, backend: str) -> None:
    """Top speeds within 2 % of fwd_speed and rev_speed (asked 2.68 m/s both ways), the
    spin's turn within turn_speed (9.4 rad/s asked), the turn at the top speed within
    turn_speed x turn_at_speed, the acceleration within drive_accel, and the stop from
    the top speed no shorter than drive_decel allows (v^2 / 2a): every profile of the
    table, on the port and (the thorough depth) on the firmware."""
    p = bench.limits(name)
    f = bench.measure({"profile": bench.PROFILES[name]}, backend)
    assert p["fwd_speed"] * 0.95 <= f["top_forward_mps"] <= p["fwd_speed"] * 1.02
    assert p["rev_speed"] * 0.95 <= f["top_backward_mps"] <= p["rev_speed"] * 1.02
    assert f["top_turn_rad_s"] <= p["turn_speed"] * 1.02
    assert f["turn_at_top_rad_s"] <= p["turn_speed"] * p["turn_at_speed"] * 1.05
    assert f["accel_mps2"] <= p["drive_accel"] * 1.02
    assert f["stopping_distance_m"] >= f["top_forward_mps"] ** 2 / (2 * p["drive_decel"])


def test_the_open_profile_limits_nothing() -> None:
    """In profile 0 the chair reaches 2.6 m/s forward and spins past 2.5 rad/s: what the
    wheels give, far past any profile above."""
    f = bench.measure({"profile": bench.PROFILES["open"]}, "port")
    assert f["top_forward_mps"] > 2.5 and f["top_turn_rad_s"] > 2.5
