"""An ISO 7176-6-style table per drive profile (docs/safety.md, "Drive limits"): what
the drive limits let the chair do on the level, measured on the plant's ground truth,
on the port and on the compiled firmware in simavr.

    python benchmarks/drive_profiles.py [--backend port|simavr|both] [--json]

A profile is a row of the board's table of drive profiles, selected by number
(``set:profile=<n>`` before the drive; the presets of protocol/spec.toml's
``[[profile]]``); ``open``, profile 0, is each limit's default, which limits nothing. Per
profile, three drives from rest on the level with an 80 kg rider, the host asking for
the chair's full speed (``MAX_LINEAR``, 2.68 m/s) or full turn:

- forward 6 s, then a stop: the top speed (the chair's centre, over 0.5 s), the time
  from the first motion to 95 % of it, the mean acceleration from 10 to 90 % of it,
  and the stopping distance and time from the top speed (``SimResult.stop_metrics``);
- backward 6 s: the top speed backward;
- a spin on the spot, 4 s at ``MAX_ANGULAR``: the top turn rate; and a turn at full
  speed (2 rad/s asked after 5 s at full speed forward): the turn rate there.

Each figure is checked against the profile's own limit in tests/sim/test_drive_profiles.py
(``--quick`` there: the port, two profiles).
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from wcdrive.protocol.spec import PROFILE_PARAMETERS, real
from wcdrive.protocol.spec import PROFILES as PRESETS
from wcdrive.sim import runner
from wcdrive.sim.scenario import Scenario, Segment

#: The profiles measured, by name: their numbers in the board's table.
PROFILES: dict[str, int] = {p.name: number for number, p in enumerate(PRESETS)}


def limits(name: str) -> dict[str, float]:
    """Profile ``name``'s drive limits as its preset sets them."""
    return dict(zip(PROFILE_PARAMETERS, PRESETS[PROFILES[name]].values, strict=True))
FULL = real("MAX_LINEAR")
SPIN = real("MAX_ANGULAR")
WINDOW_S = 0.5


def _run(params: dict[str, float], segments: list[tuple[str, tuple[float, ...], float]],
         backend: str) -> runner.SimResult:
    sc = Scenario("profile", "", tuple(Segment(*s) for s in segments), settle_s=0.5,
                  board_params=dict(params))
    return runner.run(sc, backend=backend)


def _speeds(r: runner.SimResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tick times, the chair's signed speed along its heading, its turn rate), each
    averaged over WINDOW_S."""
    t = r.board.tick_time
    pose = r.truth.pose
    dt = np.diff(t)
    ahead = (np.diff(pose[:, 0]) * np.cos(pose[1:, 2]) + np.diff(pose[:, 1]) * np.sin(pose[1:, 2])) / dt
    turn = np.diff(np.unwrap(pose[:, 2])) / dt
    n = max(1, round(WINDOW_S / float(np.median(dt))))
    kernel = np.ones(n) / n
    return t[1:], np.convolve(ahead, kernel, "same"), np.convolve(turn, kernel, "same")


def measure(params: dict[str, float], backend: str) -> dict[str, float]:
    """The profile's figures (module docstring) on ``backend``."""
    out: dict[str, float] = {}
    fwd = _run(params, [("cmdvel", (FULL, 0.0), 6.0), ("stop", (), 4.0)], backend)
    t, ahead, _ = _speeds(fwd)
    top = float(ahead.max())
    def first(share: float) -> float:
        return float(t[np.argmax(ahead >= share * top)])

    start = float(t[np.argmax(ahead > 0.02)])
    stop = fwd.stop_metrics()
    out.update(top_forward_mps=top, to_95_s=first(0.95) - start,
               accel_mps2=0.8 * top / (first(0.9) - first(0.1)),
               stopping_distance_m=float(stop["stopping_distance_m"]),
               stopping_time_s=float(stop["stopping_time_s"]))
    back = _run(params, [("cmdvel", (-FULL, 0.0), 6.0), ("stop", (), 2.0)], backend)
    out["top_backward_mps"] = float(-_speeds(back)[1].min())
    spin = _run(params, [("cmdvel", (0.0, SPIN), 4.0), ("stop", (), 2.0)], backend)
    out["top_turn_rad_s"] = float(np.abs(_speeds(spin)[2]).max())
    turn = _run(params, [("cmdvel", (FULL, 0.0), 5.0), ("cmdvel", (FULL, 2.0), 3.0), ("stop", (), 3.0)],
                backend)
    t, ahead, rate = _speeds(turn)
    late = (t > 0.5 + 5.0 + 1.5) & (t < 0.5 + 8.0)
    out["turn_at_top_rad_s"] = float(np.abs(rate[late]).mean())
    out["speed_in_turn_mps"] = float(ahead[late].mean())
    return out


def table(results: dict[str, dict[str, dict[str, float]]]) -> str:
    """Markdown: a row per profile and backend."""
    rows = ["| profile | backend | top forward (m/s) | top backward (m/s) | to 95 % (s) "
            "| acceleration, 10 to 90 % (m/s²) | stopping from top (m / s) | top turn (rad/s) "
            "| turn at top speed (rad/s, at m/s) |",
            "|---|---|---:|---:|---:|---:|---|---:|---|"]
    for name, by_backend in results.items():
        for backend, f in by_backend.items():
            rows.append(f"| {name} | {backend} | {f['top_forward_mps']:.2f} | {f['top_backward_mps']:.2f} "
                        f"| {f['to_95_s']:.2f} | {f['accel_mps2']:.2f} "
                        f"| {f['stopping_distance_m']:.2f} / {f['stopping_time_s']:.2f} "
                        f"| {f['top_turn_rad_s']:.2f} "
                        f"| {f['turn_at_top_rad_s']:.2f} at {f['speed_in_turn_mps']:.2f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", choices=("port", "simavr", "both"), default="both")
    ap.add_argument("--profiles", nargs="*", default=list(PROFILES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    backends = ("port", "simavr") if args.backend == "both" else (args.backend,)
    results = {name: {b: measure({"profile": PROFILES[name]}, b) for b in backends}
               for name in args.profiles}
    if args.json:
        print(json.dumps(results, indent=1))
    else:
        print(table(results))
        for name in args.profiles:
            values = ", ".join(f"{k} {v}" for k, v in limits(name).items())
            print(f"\n{name} (profile {PROFILES[name]}): {values}")
    bad = [k for by_b in results.values() for f in by_b.values()
           for k, v in f.items() if not math.isfinite(v)]
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
