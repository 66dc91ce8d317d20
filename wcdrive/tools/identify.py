"""``wcdrive bench identify``: a ``[chair]`` table fitted to bench recordings, and the
prediction check of ``wcdrive bench replay --plant``.

    wcdrive bench identify blocks.wcrec.json floor.wcrec.json --out chair.toml
    wcdrive bench replay held_out.wcrec.json --plant chair.toml

A recording (``wcdrive bench run ... --record``) holds the board's feedback and ``TLM:``
lines: each control tick's encoder counts (``ENC:``) and the duty and direction it
wrote (``TLM:``, protocol v2 and later). ``run_of`` turns one into a
``wcdrive.plant.identify.Run``; ``wcdrive.plant.identify.identify`` fits the plant to
the runs (which figures, how, and what cannot be told: that module's docstring and
docs/bench.md). A recording is on blocks when its scenario's name says ``blocks``
(``ident_blocks``) or ``--blocks`` names it; on the floor otherwise.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wcdrive.errors import WcdriveFileError
from wcdrive.plant.identify import GAP, Fit, Run, identify, simulate
from wcdrive.plant.params import ChairFileError, ChairParams, chair_toml, load_chair
from wcdrive.protocol.codec import Boot, ExtendedTelemetry, Feedback, LineDecoder
from wcdrive.transports.recording import Recording


class RecordingError(WcdriveFileError):
    """A recording cannot be fitted (no TLM lines, a board reset, too short)."""


def run_of(recording: Recording, *, blocks: bool | None = None, counts_per_rev: int | None = None,
           name: str = "") -> Run:
    """The ``Run`` of a recording: every tick whose ``ENC:`` line is followed by its
    ``TLM:`` line (a tick with either line lost is left out: the interval around it
    widens, and is ``lost`` unless the board's ``late`` count says a tick ran late
    there), from the first such tick after the board's boot up to a reset. The board
    stamps each tick with its own ``millis()``, so when a line reached the host does not
    matter. ``blocks`` None: from the scenario's name in the recording's meta."""
    cpr = counts_per_rev or ChairParams().counts_per_rev
    rows: list[tuple[int, int, int, int, int, int]] = []
    feedback: Feedback | None = None
    boots = 0
    for msg in LineDecoder().feed(recording.received_bytes):
        if isinstance(msg, Boot):
            boots += 1
            if boots > 1:
                break                                   # a reset: the chair's state is lost
        if isinstance(msg, Feedback):
            feedback = msg
            continue
        if isinstance(msg, ExtendedTelemetry) and feedback is not None:
            if not rows or msg.millis > rows[-1][0]:
                rows.append((msg.millis, msg.pwm_left * (1 if msg.dir_left else -1),
                             msg.pwm_right * (1 if msg.dir_right else -1),
                             -feedback.count_left, feedback.count_right,   # the left counts down forward
                             msg.late))
        feedback = None
    if len(rows) < 3:
        raise RecordingError(f"{name or 'the recording'}: fewer than 3 ticks with ENC and TLM lines "
                             "(a protocol v1 board sends no TLM; bench identify needs v2 or later)")
    data = np.array(rows, dtype=np.int64)
    if blocks is None:
        blocks = "blocks" in str(recording.meta.get("scenario", ""))
    angle = (data[:, 3:5] - data[0, 3:5]) * (2.0 * math.pi / cpr)
    # a long interval is a lost tick unless the board counted a late tick in it (then the
    # duty held all along, and is known)
    intervals = np.diff(data[:, 0])
    lost = (intervals > GAP * np.median(intervals)) & (np.diff(data[:, 5]) == 0)
    return Run(millis=data[:, 0], duty=data[:, 1:3].astype(float), angle=angle, blocks=blocks,
               name=name, lost=lost)


def load_runs(paths: Sequence[Path], blocks: Sequence[Path] = (), floor: Sequence[Path] = (),
              counts_per_rev: int | None = None) -> list[Run]:
    """``run_of`` for each recording file; ``blocks`` and ``floor`` name files whose
    experiment the scenario's name does not tell."""
    runs = []
    for path in paths:
        on: bool | None = True if path in blocks else False if path in floor else None
        runs.append(run_of(Recording.load(path), blocks=on, counts_per_rev=counts_per_rev,
                           name=path.name))
    return runs


@dataclass(frozen=True)
class Prediction:
    """How well a plant predicts a run's wheels from the board's duty: the RMS of the
    wheels' mean speeds over the tick intervals, simulated less measured (rad/s), and
    the gap between where the wheels' odometry ends up, simulated and measured (m)."""

    speed_rms: float
    end_gap: float


def predict(params: ChairParams, run: Run) -> Prediction:
    """The ``Prediction`` of ``params`` for ``run``: the plant driven tick by tick by the
    duty the board wrote (open loop: the board's PID is not re-run)."""
    sim = simulate(params, run)
    dt = np.diff(run.millis)[:, None] / 1000.0
    err = (np.diff(sim, axis=0) - np.diff(run.angle, axis=0)) / dt
    return Prediction(float(np.sqrt(np.mean(err**2))),
                      _odometry_gap(params, sim, run.angle))


def _odometry_gap(p: ChairParams, a: np.ndarray, b: np.ndarray) -> float:
    """m between the ends of two wheel-angle histories' dead reckoning."""
    def end(angles: np.ndarray) -> np.ndarray:
        d = np.diff(angles, axis=0) * p.wheel_radius
        heading = np.concatenate([[0.0], np.cumsum((d[:, 1] - d[:, 0]) / p.wheelbase)[:-1]])
        forward = 0.5 * (d[:, 0] + d[:, 1])
        return np.array([np.sum(forward * np.cos(heading)), np.sum(forward * np.sin(heading))])
    return float(np.hypot(*(end(a) - end(b))))


def chair_file_text(fit: Fit, sources: Sequence[str]) -> str:
    """The chair file ``bench identify`` writes: the fit's report as comments, then the
    ``[chair]`` table, each fitted line with its uncertainty."""
    comments = {}
    for n, v in fit.values.items():
        field = "top_wheel_speed" if n == "motor_constant" else n
        rel = fit.sigma[n] / abs(v) if v else math.inf
        note = f"{n} = {v:.6g} +- {100 * rel:.2f} %" if field != n else f"+- {100 * rel:.2f} %"
        comments[field] = note + ("  NOT PINNED DOWN" if n in fit.unpinned else "")
    header = "Fitted by wcdrive bench identify to " + ", ".join(sources) + "\n" + fit.report()
    return chair_toml(fit.overrides(), comments, header=header)


def identify_main(args: argparse.Namespace) -> int:
    """``wcdrive bench identify``: prints the fit, writes ``--out``. 0 done, 2 error,
    1 when a fitted figure was not pinned down (the file is still written)."""
    try:
        start = load_chair(args.start) if args.start else ChairParams()
        runs = load_runs(args.recordings, args.blocks or (), args.floor or (), start.counts_per_rev)
    except (OSError, ValueError) as exc:
        print(f"wcdrive bench identify: {exc}", file=sys.stderr)
        return 2
    for run in runs:
        print(f"{run.name}: {len(run.millis)} ticks, {run.duration:.1f} s, "
              f"{'on blocks' if run.blocks else 'on the floor'}")
    fit = identify(runs, start)
    print(fit.report())
    if args.out:
        Path(args.out).write_text(chair_file_text(fit, [str(p) for p in args.recordings]))
        print(f"chair file: {args.out}")
    if fit.unpinned:
        print(f"not pinned down: {', '.join(fit.unpinned)} (longer or richer runs; "
              "docs/bench.md)", file=sys.stderr)
        return 1
    return 0


def prediction_main(recording: Path, plant: Path, blocks: bool | None = None) -> int:
    """``wcdrive bench replay REC --plant chair.toml``: the prediction error of the
    chair file's plant beside the default plant's. 0 done, 2 error."""
    try:
        fitted = load_chair(plant)
        run = run_of(Recording.load(recording), blocks=blocks, counts_per_rev=fitted.counts_per_rev,
                     name=recording.name)
    except (OSError, ValueError, ChairFileError) as exc:
        print(f"wcdrive bench replay: {exc}", file=sys.stderr)
        return 2
    mine, default = predict(fitted, run), predict(ChairParams(), run)
    where = "on blocks" if run.blocks else "on the floor"
    print(f"{run.name}: {len(run.millis)} ticks, {run.duration:.1f} s {where}; the plant driven by "
          "the board's duty, tick by tick")
    print(f"  {'plant':<22} {'wheel speed RMS (rad/s)':>24} {'odometry end gap (m)':>22}")
    print(f"  {plant!s:<22} {mine.speed_rms:>24.4f} {mine.end_gap:>22.3f}")
    print(f"  {'default':<22} {default.speed_rms:>24.4f} {default.end_gap:>22.3f}")
    ratio = default.speed_rms / mine.speed_rms if mine.speed_rms > 0 else math.inf
    print(f"  the fitted plant's speed error is {ratio:.1f}x smaller than the default's")
    return 0
