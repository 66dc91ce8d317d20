"""``wcdrive sweep SPEC.toml``: many closed-loop runs (``wcdrive sim``) on Dask, one
table row per run.

A spec is TOML::

    scenarios = ["step_response", "square"]   # bundled names or .toml paths
    backends = ["port"]                        # "port" and/or "simavr"
    seeds = [0, 1, 2]                          # or a count: seeds = 10 (0..9)
    dt = 0.002                                 # physics step, s (default 0.001)
    mode = "grid"                              # or "random", with samples = N
    samples = 50                               # random: how many runs
    sample_seed = 0                            # random: the draw's seed

    [params]                                   # board parameters (set:), per run
    kp = [1.0, 2.0, 4.0]                       # grid: every value; random: one of them
    ki = { min = 0.5, max = 3.0 }              # random only: uniform in [min, max]

    [chair]                                    # ChairParams overrides, the same way
    mass = [90.0, 120.0]

``grid`` runs every combination (scenarios x backends x seeds x params x chair);
``random`` draws ``samples`` combinations. Each run is a task on a Dask cluster: a
``LocalCluster`` on this machine by default, or ``--scheduler tcp://HOST:8786``
(``--serial`` runs them in this process, without Dask). Each row has the run's index,
its inputs (``scenario``, ``backend``, ``seed``, ``param.<name>``, ``chair.<name>``)
and the metrics of ``wcdrive sim --json`` (those that are lists, the board's events
among them, as JSON strings), or ``error`` for a run that raised. Rows are written as
CSV or Parquet (``--out``, by its suffix), sorted by run index. Ctrl-C cancels the runs
not done and writes the finished ones.

A program may build the runs itself and give each its scenario as TOML text: a point
of ``expand``'s form whose ``toml`` is the scenario file's text (``scenario`` then only
names it in the row); ``run_one``, ``run_serial`` and ``run_dask`` take such points as
they are (``benchmarks/envelope.py`` generates its drives so).
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import logging
import math
import random
import tempfile
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from wcdrive.errors import WcdriveConnectionError, WcdriveFileError
from wcdrive.firmware.params import PARAMS
from wcdrive.plant.params import ChairParams
from wcdrive.sim import report, runner, scenario

log = logging.getLogger("wcdrive.sweep")

#: Columns that depend on the wall clock, so differ between two runs of the same inputs.
WALL_CLOCK_COLUMNS = ("real_time_factor", "wall_s")
_SPEC_KEYS = {"scenarios", "backends", "seeds", "dt", "mode", "samples", "sample_seed", "params", "chair"}


class SpecError(WcdriveFileError):
    """A sweep spec is missing, malformed or names an unknown scenario, parameter or
    chair field; the message says which."""


@dataclasses.dataclass(frozen=True)
class Spec:
    """A loaded spec (module docstring)."""

    scenarios: tuple[str, ...]
    backends: tuple[str, ...] = ("port",)
    seeds: tuple[int, ...] = (0,)
    dt: float = 0.001
    mode: str = "grid"
    samples: int = 0
    sample_seed: int = 0
    params: dict[str, list[float] | tuple[float, float]] = dataclasses.field(default_factory=dict)
    chair: dict[str, list[float] | tuple[float, float]] = dataclasses.field(default_factory=dict)


def _axis(where: str, name: str, value: object, mode: str) -> list[float] | tuple[float, float]:
    if isinstance(value, list) and value and all(isinstance(v, int | float) and not isinstance(v, bool)
                                                 for v in value):
        return [float(v) for v in value]
    if isinstance(value, int | float) and not isinstance(value, bool):
        return [float(value)]
    if isinstance(value, dict) and set(value) == {"min", "max"}:
        if mode != "random":
            raise SpecError(f"{where}.{name}: a {{min, max}} range needs mode = \"random\"")
        lo, hi = float(value["min"]), float(value["max"])
        if not lo <= hi:
            raise SpecError(f"{where}.{name}: min must be <= max")
        return (lo, hi)
    raise SpecError(f"{where}.{name}: give a number, a list of numbers or {{ min = a, max = b }}")


def load_spec(path: str | Path) -> Spec:
    """Reads and checks a spec file (``SpecError`` names what is wrong)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError as exc:
        raise SpecError(f"{p}: no such file") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{p}: not valid TOML: {exc}") from exc
    unknown = set(data) - _SPEC_KEYS
    if unknown:
        raise SpecError(f"{p}: unknown keys {', '.join(sorted(unknown))} (a spec takes "
                        f"{', '.join(sorted(_SPEC_KEYS))})")
    names = data.get("scenarios")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise SpecError(f"{p}: scenarios must be a list of bundled names or .toml paths")
    for name in names:
        try:
            scenario.load(str(p.parent / name) if name.endswith(".toml") else name)
        except scenario.ScenarioError as exc:
            raise SpecError(f"{p}: {exc}") from exc
    backends = data.get("backends", ["port"])
    if not isinstance(backends, list) or not set(backends) <= {"port", "simavr"} or not backends:
        raise SpecError(f"{p}: backends must be a list of \"port\" and/or \"simavr\"")
    seeds = data.get("seeds", [0])
    if isinstance(seeds, int) and not isinstance(seeds, bool) and seeds >= 1:
        seeds = list(range(seeds))
    if not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) for s in seeds):
        raise SpecError(f"{p}: seeds must be a list of integers or a count >= 1")
    mode = data.get("mode", "grid")
    if mode not in ("grid", "random"):
        raise SpecError(f"{p}: mode must be \"grid\" or \"random\"")
    samples = data.get("samples", 0)
    if mode == "random" and (not isinstance(samples, int) or samples < 1):
        raise SpecError(f"{p}: mode = \"random\" needs samples = N (>= 1)")
    params = {k: _axis("params", k, v, mode) for k, v in dict(data.get("params", {})).items()}
    known_params = {q.name for q in PARAMS}
    bad = set(params) - known_params
    if bad:
        raise SpecError(f"{p}: unknown [params] {', '.join(sorted(bad))} (the board's parameters: "
                        f"{', '.join(sorted(known_params))})")
    chair = {k: _axis("chair", k, v, mode) for k, v in dict(data.get("chair", {})).items()}
    fields = {f.name for f in dataclasses.fields(ChairParams)}
    bad = set(chair) - fields
    if bad:
        raise SpecError(f"{p}: unknown [chair] fields {', '.join(sorted(bad))}")
    dt = float(data.get("dt", 0.001))
    if not 1e-5 <= dt <= 0.01:
        raise SpecError(f"{p}: dt must be within 1e-5 .. 0.01 s")
    resolved = tuple(str(p.parent / n) if n.endswith(".toml") else n for n in names)
    return Spec(scenarios=resolved, backends=tuple(backends), seeds=tuple(seeds), dt=dt, mode=mode,
                samples=int(samples), sample_seed=int(data.get("sample_seed", 0)), params=params,
                chair=chair)


def expand(spec: Spec) -> list[dict[str, Any]]:
    """The runs of ``spec``, each a dict: ``run`` (index), ``scenario``, ``backend``,
    ``seed``, ``dt``, ``params`` and ``chair`` (name -> value)."""
    if spec.mode == "grid":
        pnames, cnames = list(spec.params), list(spec.chair)
        combos = itertools.product(spec.scenarios, spec.backends, spec.seeds,
                                   itertools.product(*(spec.params[n] for n in pnames)),
                                   itertools.product(*(spec.chair[n] for n in cnames)))
        points = [{"scenario": sc, "backend": be, "seed": seed, "dt": spec.dt,
                   "params": dict(zip(pnames, pv, strict=True)), "chair": dict(zip(cnames, cv, strict=True))}
                  for sc, be, seed, pv, cv in combos]
    else:
        rng = random.Random(spec.sample_seed)

        def pick(axis: list[float] | tuple[float, float]) -> float:
            return rng.uniform(*axis) if isinstance(axis, tuple) else rng.choice(axis)

        points = [{"scenario": rng.choice(spec.scenarios), "backend": rng.choice(spec.backends),
                   "seed": rng.choice(spec.seeds), "dt": spec.dt,
                   "params": {n: pick(a) for n, a in spec.params.items()},
                   "chair": {n: pick(a) for n, a in spec.chair.items()}} for _ in range(spec.samples)]
    return [{"run": i, **pt} for i, pt in enumerate(points)]


def run_one(point: dict[str, Any]) -> dict[str, Any]:
    """One run of ``expand``'s list, as its table row (a run that raises gives a row
    with ``error``). Runs in a Dask worker, or here with ``--serial``. A point with a
    ``toml`` (the module docstring) runs that text, not the file ``scenario`` names."""
    row: dict[str, Any] = {"run": point["run"], "scenario": point["scenario"], "backend": point["backend"],
                           "seed": point["seed"]}
    row.update({f"param.{k}": v for k, v in point["params"].items()})
    row.update({f"chair.{k}": v for k, v in point["chair"].items()})
    wall0 = time.perf_counter()
    try:
        sc = _load(point)
        sc = dataclasses.replace(sc, board_params={**sc.board_params, **point["params"]},
                                 chair={**sc.chair, **point["chair"]})
        result = runner.run(sc, backend=point["backend"], seed=point["seed"], dt=point["dt"])
        metrics = json.loads(report.to_json([result]))[0]
    except Exception as exc:
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["wall_s"] = round(time.perf_counter() - wall0, 3)
        return row
    for key in ("scenario", "backend"):
        metrics.pop(key, None)
    for key, value in metrics.items():
        if isinstance(value, list):                    # events, boots, ramps, slope_by_time
            metrics[key] = json.dumps(value)
    row.update(metrics)
    row["error"] = ""
    row["wall_s"] = round(time.perf_counter() - wall0, 3)
    return row


def _load(point: dict[str, Any]) -> scenario.Scenario:
    """The point's scenario: its ``toml`` text, or the file ``scenario`` names."""
    text = point.get("toml")
    if text is None:
        return scenario.load(point["scenario"])
    with tempfile.TemporaryDirectory(prefix="wcdrive-sweep-") as tmp:
        path = Path(tmp) / "scenario.toml"
        path.write_text(text)
        return scenario.load(str(path))


def run_serial(points: Iterable[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """The rows, one run after the other in this process."""
    for point in points:
        yield run_one(point)


def connect_scheduler(address: str) -> Any:
    """A Dask ``Client`` of the scheduler at ``address``, or ``WcdriveConnectionError``
    saying how to start one."""
    from dask.distributed import Client

    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise WcdriveConnectionError(
            f"cannot reach the Dask scheduler at {address}: {exc} (start one with "
            "`dask scheduler` and workers with `dask worker <address>`)") from exc


def run_dask(points: list[dict[str, Any]], scheduler: str | None = None, workers: int | None = None
             ) -> Iterator[dict[str, Any]]:
    """The rows as their runs finish on Dask: the cluster at ``scheduler``
    (tcp://HOST:PORT), or a ``LocalCluster`` of ``workers`` processes (default: one per
    core). Closing the iterator early (Ctrl-C) cancels the runs not done."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler:
        log.info("sweep: connecting to the Dask scheduler at %s", scheduler)
        client = connect_scheduler(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        log.info("sweep: a LocalCluster of %d workers", len(cluster.workers))
    futures = client.map(run_one, points, pure=False)
    try:
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.cancel(futures)
        client.close()
        if cluster is not None:
            cluster.close()


def columns(rows: list[dict[str, Any]]) -> list[str]:
    """Every column of ``rows``, in the order they first appear."""
    out: dict[str, None] = {}
    for row in rows:
        out.update(dict.fromkeys(row))
    return list(out)


def write(rows: list[dict[str, Any]], path: Path) -> Path:
    """Writes ``rows`` (sorted by run) as CSV, or Parquet for a ``.parquet`` path
    (needs pandas and pyarrow: ``pip install wcdrive[parquet]``)."""
    rows = sorted(rows, key=lambda r: r["run"])
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".parquet":
        try:
            import pandas as pd
        except ImportError as exc:
            raise SpecError("Parquet output needs pandas and pyarrow: "
                            "pip install 'wcdrive[parquet]'") from exc
        try:
            pd.DataFrame(rows, columns=columns(rows)).to_parquet(path, index=False)
        except ImportError as exc:
            raise SpecError("Parquet output needs pyarrow: pip install 'wcdrive[parquet]'") from exc
        return path
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns(rows), restval="")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    return path


def read_csv(path: Path) -> list[dict[str, str]]:
    """A written CSV's rows, as text."""
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def collect(rows: Iterator[dict[str, Any]], on_row: Callable[[dict[str, Any]], None] | None = None
            ) -> tuple[list[dict[str, Any]], bool]:
    """Takes rows until the iterator ends or Ctrl-C; returns (rows, interrupted). The
    iterator is closed either way (for Dask: the runs not done are cancelled)."""
    done: list[dict[str, Any]] = []
    try:
        for row in rows:
            done.append(row)
            if on_row:
                on_row(row)
    except KeyboardInterrupt:
        return done, True
    finally:
        close = getattr(rows, "close", None)
        if close:
            close()
    return done, False


def throughput(rows: list[dict[str, Any]], seconds: float) -> float:
    """Runs per wall second."""
    return len(rows) / seconds if seconds > 0 else math.inf
