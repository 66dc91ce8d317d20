"""Fitting ``ChairParams`` to what a board did: its duty per control tick and its wheels'
angles at each tick (``Run``), the wheels on blocks or on the floor.

    fit = identify([run_on_blocks, run_on_floor])     # -> Fit
    fit.params                                        # ChairParams with the fitted figures
    print(fit.report())

The fit is a simulation-error fit (``scipy.optimize.least_squares``): each run is
re-simulated from rest, driven by its recorded duty tick by tick, and the residuals are
the wheels' mean speeds over each tick interval, simulated less measured (rad/s), with
the plant's own equation of motion (``wcdrive.plant.identify_model``; the runs
themselves: ``wcdrive.plant.identify_run``).

What the counts can tell apart (docs/bench.md has the reasoning). The motor's torque is
``Kt (V - Ke G w) / R`` with ``Kt = eta G Ke`` at the wheel, against ``J dw/dt + b w``
and, on the floor, the body. Multiplying ``Kt/R``, the inertias, the masses, ``b`` and
the driver's current limit's torque together changes no motion, so one scale is not
identifiable; the gear ratio, its efficiency and the armature resistance are held at
their defaults and fix it. Viscous gear friction adds ``b R / Kt`` (0.4 % for the
defaults) to the back-EMF constant in every steady speed and time constant alike, so
``b`` is held too. The drive wheels' and the casters' rolling resistance are one force
``m g (crr (1 - s) + crr_c s)``: ``crr_c`` is held. Chair and occupant are one mass:
the occupant is held. Then, with ``FITTED``:

* blocks: ``motor_constant`` (as ``top_wheel_speed``, which sets it), ``wheel_inertia``,
  ``current_limit``;
* floor: ``motor_constant``, ``current_limit``, ``chair_mass``, ``rolling_resistance``;
  ``wheel_inertia`` only weakly (6 % of what a wheel drives on the floor), so it is
  fitted only when a run on blocks is given.

Each fitted figure has a standard uncertainty from the fit's Jacobian (residuals taken
as independent: an underestimate where they are correlated), widened to half the spread
of the fits from other starts that end within ``RIVAL`` of the best cost; one beyond
``PIN_LIMIT`` is reported as not pinned down (``wcdrive.plant.identify_uncertainty``).
The model's and the runs' names are importable from here too.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from wcdrive.plant.identify_model import (
    DT,
    ROBUST_SCALE,
    apply,
    block_wheel_step,
    residuals,
    rms,
    simulate,
    value,
    with_motor_constant,
)
from wcdrive.plant.identify_run import GAP, GAP_SETTLE, Run, degraded
from wcdrive.plant.identify_uncertainty import _standard_errors, _uncertainty_scale
from wcdrive.plant.params import ChairParams

__all__ = ["BLOCKS_FITS", "BODY_KEEP", "BODY_LOSS", "BODY_SCAN", "CONSIDER", "DT", "FITTED", "FLOOR_FITS",
           "GAP", "GAP_SETTLE", "HELD", "MOTOR_STARTS", "PIN_LIMIT", "RIVAL", "ROBUST_SCALE", "STAGES",
           "Fit", "Run", "apply", "block_wheel_step", "degraded", "identify", "residuals", "rms",
           "simulate", "value", "wheel_factors", "with_motor_constant"]

#: The figures a fit may move, in the order the fit keeps them; ``motor_constant`` is
#: written as the ``top_wheel_speed`` that gives it.
FITTED = ("motor_constant", "wheel_inertia", "current_limit", "chair_mass", "rolling_resistance")
#: The fit's stages: the figures each frees (``()``: all of them).
STAGES: tuple[tuple[str, ...], ...] = (("motor_constant",), ("motor_constant", "current_limit"), ())
#: The body's scan: factors on the start's chair_mass and rolling_resistance, every pair
#: simulated once on the floor's runs; the fit starts from the ``BODY_KEEP`` pairs of
#: lowest robust cost. The floor's cost is rugged (a wheel starting to slip at full duty
#: moves by a tick as the body changes), with false valleys a few % across.
BODY_SCAN = tuple(float(f) for f in np.geomspace(0.5, 2.0, 8))
BODY_KEEP = 5
#: The body's fits' loss: the robust loss of the final fit, under which a few ticks
#: around the slip cannot carve the false valleys that they carve in plain least squares.
BODY_LOSS = "soft_l1"
#: A start that ends within this factor of the best robust cost is a rival: where the
#: rivals disagree on a figure, half their spread counts in its uncertainty.
RIVAL = 1.1
#: On the floor alone, the scan at each of these factors on the start's motor constant.
MOTOR_STARTS = (1.0, 0.8, 1.25)
#: Which runs tell each fitted figure.
BLOCKS_FITS = ("motor_constant", "wheel_inertia", "current_limit")
FLOOR_FITS = ("motor_constant", "current_limit", "chair_mass", "rolling_resistance")
#: Held at their defaults (or the starting chair's), with why.
HELD = {
    "gear_ratio": "with gear_efficiency and armature_resistance: one scale of torque, inertia and "
                  "mass that no motion shows",
    "gear_efficiency": "as gear_ratio",
    "armature_resistance": "as gear_ratio (measure it with an ohmmeter and start from it)",
    "viscous_friction": "adds b R / Kt to the back-EMF constant in every speed alike",
    "rotor_inertia": "one inertia with wheel_inertia",
    "caster_rolling_resistance": "one force with rolling_resistance",
    "occupant_mass": "one mass with chair_mass",
    "supply_voltage": "the duty's scale: measure the battery (battery_voltage)",
}
#: Held figures that some runs cannot fix and that move the fitted ones: when held, each
#: one's relative uncertainty (the default's is a guess, "typical rather than measured")
#: is carried into the fitted figures' uncertainties.
CONSIDER = {"wheel_inertia": 0.3}
#: A fitted figure whose relative standard uncertainty passes this is not pinned down.
PIN_LIMIT = 0.02


@dataclass
class Fit:
    """What ``identify`` found: ``params`` (the start with the fitted figures),
    ``values`` and ``sigma`` (standard uncertainties, same units) of each fitted figure,
    ``held`` the figures kept at the start's, ``rms`` (rad/s) each run's residual
    speed RMS before and after, ``wheel_factor`` each wheel's back-EMF constant over
    the mean (with its uncertainty), and ``unpinned``: fitted figures whose relative
    uncertainty passed ``PIN_LIMIT``."""

    params: ChairParams
    start: ChairParams
    values: dict[str, float]
    sigma: dict[str, float]
    held: dict[str, str]
    rms_before: dict[str, float]
    rms_after: dict[str, float]
    wheel_factor: dict[str, tuple[float, float]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def unpinned(self) -> list[str]:
        """Fitted figures the runs did not pin down (relative uncertainty > ``PIN_LIMIT``)."""
        return [n for n, v in self.values.items() if not self.sigma[n] <= PIN_LIMIT * abs(v)]

    def overrides(self) -> dict[str, float]:
        """The ``[chair]`` table: the fitted figures as ``ChairParams`` fields
        (``motor_constant`` as ``top_wheel_speed``), the rest as the start has them."""
        names = [n for n in self.values if n != "motor_constant"]
        if "motor_constant" in self.values:
            names.insert(0, "top_wheel_speed")
        start = dataclasses.asdict(self.start)
        default = dataclasses.asdict(ChairParams())
        out = {n: float(getattr(self.params, n)) for n in names}
        out.update({n: v for n, v in start.items() if v != default[n] and n not in out})
        return out

    def report(self) -> str:
        """The fit as text: each figure with its uncertainty, what was held and why,
        per-wheel factors and each run's residuals."""
        lines = ["fitted (value +- standard uncertainty; default):"]
        default = ChairParams()
        for n, v in self.values.items():
            s = self.sigma[n]
            rel = s / abs(v) if v else math.inf
            flag = "" if rel <= PIN_LIMIT else "   NOT PINNED DOWN by these runs"
            lines.append(f"  {n:<20} {v:.6g} +- {s:.2g} ({100 * rel:.2f} %; default "
                         f"{value(default, n):.6g}){flag}")
        if "motor_constant" in self.values:
            lines.append("  (motor_constant is written as top_wheel_speed = "
                         f"{self.params.top_wheel_speed:.6g})")
        lines.append("held (not identifiable from duty and encoder counts):")
        for n, why in self.held.items():
            lines.append(f"  {n:<26} {getattr(self.params, n)!r:<10} {why}")
        if self.wheel_factor:
            lines.append("per-wheel back-EMF factor (each wheel's over the mean; the plant has one "
                         "motor model for both wheels):")
            for side, (f, s) in self.wheel_factor.items():
                lines.append(f"  {side:<6} {f:.4f} +- {s:.4f}")
        lines.append("residual wheel-speed RMS per run (rad/s), start -> fitted:")
        for name in self.rms_after:
            lines.append(f"  {name}: {self.rms_before[name]:.4f} -> {self.rms_after[name]:.4f}")
        lines += [f"note: {note}" for note in self.notes]
        return "\n".join(lines)


def identify(runs: Sequence[Run], start: ChairParams | None = None) -> Fit:
    """Fits the figures the runs can tell (module docstring) to all ``runs`` at once,
    from ``start`` (default ``ChairParams()``), the rest held at ``start``'s. Raises
    ValueError without a run."""
    if not runs:
        raise ValueError("no runs to fit")
    start = start or ChairParams()
    blocks = any(r.blocks for r in runs)
    floor = any(not r.blocks for r in runs)
    names = [n for n in FITTED if (blocks and n in BLOCKS_FITS) or (floor and n in FLOOR_FITS)]
    held = dict(HELD)
    notes = []
    if not blocks:
        held["wheel_inertia"] = ("weakly seen on the floor (6 % of the driven inertia): fitted "
                                 "from runs on blocks")
    if not floor:
        held["chair_mass"] = "invisible on blocks: fitted from runs on the floor"
        held["rolling_resistance"] = "invisible on blocks: fitted from runs on the floor"
    x0 = np.array([math.log(value(start, n)) for n in names])

    def params_of(x: np.ndarray) -> ChairParams:
        return apply(start, {n: math.exp(v) for n, v in zip(names, x, strict=True)})

    def fun(x: np.ndarray) -> np.ndarray:
        return residuals(params_of(x), runs)

    bounds = (x0 - math.log(5.0), x0 + math.log(5.0))
    # From far off the whole fit can settle in a false valley (a heavier chair with a
    # larger current limit and wheel inertia, say), so it is built up: the runs on
    # blocks alone fix the motor and the wheel (the motor constant alone first, then
    # with the current limit, then all of theirs); the runs on the floor then the body,
    # the rest held (on the floor alone: in the same stages as on blocks, the body freed
    # last), with ``BODY_LOSS``, from the best ``BODY_KEEP`` points of the ``BODY_SCAN``
    # grid (on the floor alone: of its points at each of ``MOTOR_STARTS``), the best
    # kept; then all figures on all runs, least squares and again with the robust loss.
    x = x0.copy()
    block_runs = [r for r in runs if r.blocks]
    floor_runs = [r for r in runs if not r.blocks]
    if block_runs:
        _, x = _staged(lambda z: residuals(params_of(z), block_runs), x, names,
                       [tuple(n for n in stage or BLOCKS_FITS if n in BLOCKS_FITS) for stage in STAGES],
                       bounds)
    spread: dict[str, float] = {}
    if floor_runs:
        def floor_fun(z: np.ndarray) -> np.ndarray:
            return residuals(params_of(z), floor_runs)

        stages = [("chair_mass", "rolling_resistance")] if block_runs else [*STAGES[:-1], ()]
        found = [_staged(floor_fun, y, names, stages, bounds, BODY_LOSS)
                 for y in _body_starts(floor_fun, x, names, (1.0,) if block_runs else MOTOR_STARTS)]
        best = min(found, key=lambda f: f[0])
        x = best[1]
        rivals = np.array([f[1] for f in found if f[0] <= RIVAL * best[0]])
        spread = {n: float(np.exp(0.5 * (rivals[:, i].max() - rivals[:, i].min())) - 1.0)
                  for i, n in enumerate(names)}
    x = least_squares(fun, x, x_scale=0.1, diff_step=1e-4, xtol=1e-10, ftol=1e-10, bounds=bounds).x
    result = least_squares(fun, x, x_scale=0.1, diff_step=1e-4, xtol=1e-10, ftol=1e-10,
                           loss="soft_l1", f_scale=ROBUST_SCALE, bounds=bounds)
    fitted = params_of(result.x)
    values = {n: value(fitted, n) for n in names}
    scale = _uncertainty_scale(runs, result.fun, start.counts_per_rev)
    rel = np.array(_standard_errors(result.jac, scale))
    considered = [n for n in CONSIDER if n not in names and n in held]
    if considered:
        base = fun(result.x)
        plain = np.stack([(fun(result.x + 1e-2 * np.eye(len(names))[i]) - base) / 1e-2
                          for i in range(len(names))], axis=1)
    for name in considered:
        prior = CONSIDER[name]
        # a figure held that these runs cannot fix but that moves the fitted ones: its
        # own uncertainty carried into theirs (a "consider" covariance, linearised)
        # over the whole of its uncertainty: the plant is not smooth on a finer scale
        nudged = {name: value(start, name) * math.exp(prior)}
        moved = apply(dataclasses.replace(start, **nudged),          # type: ignore[arg-type]
                      {n: values[n] for n in names})
        column = (residuals(moved, runs) - base) / prior
        shift, *_ = np.linalg.lstsq(plain, column, rcond=None)
        rel = np.sqrt(rel**2 + (shift * prior) ** 2)
        notes.append(f"the uncertainties include {name}'s, held at {value(start, name):.4g} "
                     f"(taken as uncertain by {100 * prior:.0f} %)")
    # rival starts that disagree: the runs cannot tell their minima apart
    rel = np.array([max(float(r), spread.get(n, 0.0)) for n, r in zip(names, rel, strict=True)])
    wide = [n for n in names if spread.get(n, 0.0) > PIN_LIMIT]
    if wide:
        notes.append("fits from different starts ended in different minima of about the same "
                     "cost: their spread counts in the uncertainties of " + ", ".join(wide))
    sigma = {n: abs(values[n]) * float(r) for n, r in zip(names, rel, strict=True)}
    if any(math.isinf(s) for s in sigma.values()):
        notes.append("some figure has no effect on these runs (its column of the Jacobian is zero)")
    if not result.success:
        notes.append(f"the optimiser stopped: {result.message}")
    fit = Fit(params=fitted, start=start, values=values, sigma=sigma, held=held,
              rms_before={r.name: rms(start, r) for r in runs},
              rms_after={r.name: rms(fitted, r) for r in runs}, notes=notes)
    if blocks:
        fit.wheel_factor = wheel_factors(fitted, [r for r in runs if r.blocks])
    return fit


def _body_starts(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, names: Sequence[str],
                 motors: Sequence[float]) -> list[np.ndarray]:
    """The ``BODY_KEEP`` points of lowest robust cost (``_robust_cost``) of ``fun`` on
    the ``BODY_SCAN`` grid: ``x`` with its motor constant times each of ``motors`` and
    its chair_mass and rolling_resistance times each pair of the grid's factors."""
    at = {n: i for i, n in enumerate(names)}
    scanned: list[tuple[float, np.ndarray]] = []
    for motor, mass, crr in itertools.product(motors, BODY_SCAN, BODY_SCAN):
        y = x.copy()
        y[at["motor_constant"]] += math.log(motor)
        y[at["chair_mass"]] += math.log(mass)
        y[at["rolling_resistance"]] += math.log(crr)
        try:
            r = fun(y)
        except ValueError:                      # no top speed gives the motor constant
            continue
        scanned.append((_robust_cost(r), y))
    scanned.sort(key=lambda c: c[0])
    return [y for _, y in scanned[:BODY_KEEP]]


def _robust_cost(r: np.ndarray) -> float:
    """``least_squares``' cost of the residuals ``r`` with its soft L1 loss at
    ``ROBUST_SCALE``."""
    z = (r / ROBUST_SCALE) ** 2
    return float(ROBUST_SCALE**2 * np.sum(np.sqrt(1.0 + z) - 1.0))


def _staged(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, names: Sequence[str],
            stages: Sequence[tuple[str, ...]], bounds: tuple[np.ndarray, np.ndarray],
            loss: str = "linear") -> tuple[float, np.ndarray]:
    """Least squares of ``fun`` from ``x`` in ``stages`` with ``loss`` (``"soft_l1"``: at
    ``ROBUST_SCALE``): each frees the figures it names (``()``: all), the others held
    where the last stage left them. Returns the last stage's cost and ``x``."""
    cost = math.inf
    x = x.copy()
    for stage in stages:
        free = [i for i, n in enumerate(names) if n in stage or stage == ()]
        if not free:
            continue

        def part(y: np.ndarray, free: list[int] = free, x: np.ndarray = x) -> np.ndarray:
            z = x.copy()
            z[free] = y
            return fun(z)

        step = least_squares(part, x[free], x_scale=0.1, diff_step=1e-4, xtol=1e-10, ftol=1e-10,
                             bounds=(bounds[0][free], bounds[1][free]), loss=loss,
                             f_scale=ROBUST_SCALE)
        x = x.copy()
        x[free] = step.x
        cost = float(step.cost)
    return cost, x


def wheel_factors(p: ChairParams, runs: Sequence[Run]) -> dict[str, tuple[float, float]]:
    """Each wheel's back-EMF constant over the mean of both, from runs on blocks (where
    the wheels are independent): a one-figure fit of ``motor_constant`` per wheel, the
    rest at ``p``'s; with its standard uncertainty."""
    out: dict[str, tuple[float, float]] = {}
    ks: list[tuple[float, float]] = []
    for side in (0, 1):
        one = [dataclasses.replace(r, duty=r.duty[:, [side, side]], angle=r.angle[:, [side, side]])
               for r in runs]

        def fun(x: np.ndarray, one: list[Run] = one) -> np.ndarray:
            return residuals(with_motor_constant(p, math.exp(x[0])), one)[::2]

        res = least_squares(fun, [math.log(p.motor_constant)], x_scale=0.1, diff_step=1e-4)
        s2 = float(res.fun @ res.fun) / max(1, res.fun.size - 1)
        jtj = float(res.jac[:, 0] @ res.jac[:, 0])
        ks.append((math.exp(res.x[0]), math.sqrt(s2 / jtj) if jtj > 0 else math.inf))
    mean = 0.5 * (ks[0][0] + ks[1][0])
    for name, (k, rel) in zip(("left", "right"), ks, strict=True):
        out[name] = (k / mean, rel * k / mean)
    return out
