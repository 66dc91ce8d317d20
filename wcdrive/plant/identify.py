"""Fitting ``ChairParams`` to what a board did: its duty per control tick and its wheels'
angles at each tick (``Run``), the wheels on blocks or on the floor.

    fit = identify([run_on_blocks, run_on_floor])     # -> Fit
    fit.params                                        # ChairParams with the fitted figures
    print(fit.report())

The fit is a simulation-error fit (``scipy.optimize.least_squares``): each run is
re-simulated from rest, driven by its recorded duty tick by tick, and the residuals are
the wheels' mean speeds over each tick interval, simulated less measured (rad/s). So the
encoder's quantisation is one count over a whole interval, a dropped tick only widens an
interval, and the equation of motion is the plant's own:

* On the floor ``simulate`` runs ``wcdrive.plant.chair.Plant`` itself (body, tyres,
  casters), 1 ms steps, the duty of tick k from ``millis[k]`` to ``millis[k+1]``.
* On blocks the drive tyres touch nothing; the wheel is the plant's wheel with no tyre
  force (``block_wheel_step``: the kernel's implicit step, ``j dw/dt = tau - b w`` with
  ``tau = Kt (V - Ke G w) / R`` held to the driver's current limit). The plant cannot be
  used for this: with no grip (``friction = 0``) its wheel step takes the current limit
  it decided with the tyre gripping, and a wheel in the air then runs away beyond its
  no-load speed (docs/bench.md, "Known limits").

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
``PIN_LIMIT`` is reported as not pinned down.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from wcdrive.plant.chair import Plant
from wcdrive.plant.params import ChairParams

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
#: s of a plant step.
DT = 0.001
#: An interval longer than this many ticks is a gap: a tick's lines were lost.
GAP = 1.5
#: s after a gap that the fit leaves out, on blocks and on the floor: the wheel in the air
#: settles within a few of its 30 ms time constants; on the floor a guessed duty's error
#: lingered in the body's motion (0.5 and 1 s left rolling resistance 8 and 5 % off
#: with 5 % of the lines lost, benchmarks/identify.py).
GAP_SETTLE = {True: 0.2, False: 2.0}
#: rad/s: residuals beyond this weigh less and less (``least_squares``' soft L1 loss): a
#: tick stamped late, a lost line's guessed duty, do not steer the fit.
ROBUST_SCALE = 0.1


@dataclass(frozen=True)
class Run:
    """One recorded experiment: ``millis`` (n) the ticks' board times in ms; ``duty``
    (n x 2, left and right) the signed duty (-255..255, + forward) each tick wrote,
    driving until the next; ``angle`` (n x 2) the wheels' angles at each tick (rad,
    forward +, from the encoder counts); ``blocks`` whether the wheels were off the
    ground. The first tick is at rest."""

    millis: np.ndarray
    duty: np.ndarray
    angle: np.ndarray
    blocks: bool
    name: str = ""
    #: (n-1) bools: the intervals over which a tick's lines were lost (its duty unknown);
    #: None: every interval longer than ``GAP`` ticks (a tick that ran late is one too).
    lost: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.millis)
        if n < 3 or self.duty.shape != (n, 2) or self.angle.shape != (n, 2):
            raise ValueError("a run needs 3 or more ticks, with a duty and an angle pair for each")
        if np.any(np.diff(self.millis) <= 0):
            raise ValueError("the ticks' millis must increase")

    @property
    def duration(self) -> float:
        """s from the first tick to the last."""
        return float(self.millis[-1] - self.millis[0]) / 1000.0

    @property
    def tick_ms(self) -> float:
        """ms of a control tick: the median interval."""
        return float(np.median(np.diff(self.millis)))

    def gaps(self) -> np.ndarray:
        """(n-1) bools: the intervals where a tick's lines were lost (its duty is not
        known): ``lost``, else those longer than ``GAP`` ticks."""
        if self.lost is not None:
            return self.lost
        return np.diff(self.millis) > GAP * self.tick_ms

    def weights(self) -> np.ndarray:
        """(n-1): 1 for an interval the fit compares, 0 for a gap and the ``GAP_SETTLE``
        s after it (the simulation guessed the lost duty: its state settles again). A
        run with many gaps keeps little: its figures come out not pinned down."""
        out = np.ones(len(self.millis) - 1)
        settle = math.ceil(GAP_SETTLE[self.blocks] * 1000.0 / self.tick_ms)
        for i in np.flatnonzero(self.gaps()):
            out[i:i + 1 + settle] = 0.0
        return out

    def schedule(self) -> list[tuple[int, float, float, int]]:
        """What drives the simulation: (steps, duty left, duty right, interval) runs of
        ``DT`` steps, each ending where the interval ``interval`` ends (-1: it does not).
        Over a gap the tick's own duty holds for a tick, then the mean of it and the
        next known one (the lost tick's, guessed)."""
        out: list[tuple[int, float, float, int]] = []
        gaps = self.gaps()
        tick = round(self.tick_ms)
        for i, n in enumerate(np.diff(self.millis).astype(int)):
            dl, dr = float(self.duty[i, 0]), float(self.duty[i, 1])
            if gaps[i]:
                out.append((tick, dl, dr, -1))
                out.append((int(n) - tick, round(0.5 * (dl + self.duty[i + 1, 0])),
                            round(0.5 * (dr + self.duty[i + 1, 1])), i))
            else:
                out.append((int(n), dl, dr, i))
        return out

    def speeds(self) -> np.ndarray:
        """(n-1) x 2: each wheel's mean speed over each interval between ticks (rad/s)."""
        return np.diff(self.angle, axis=0) / (np.diff(self.millis)[:, None] / 1000.0)


def block_wheel_step(p: ChairParams, volts: float, speed: float, dt: float = DT) -> float:
    """A wheel on blocks one step of ``dt`` on from ``speed`` (rad/s) at ``volts``: the
    plant's implicit wheel step with no tyre force. The unlimited solution of
    ``j (w - speed) / dt = k1 V - (k2 + b) w``; where its current would pass the limit,
    the limit's torque instead: ``j (w - speed) / dt = +-tau_max - b w``."""
    k = p.motor_constant
    ke_g = k * p.gear_ratio
    k1 = p.gear_ratio * p.gear_efficiency * k / p.armature_resistance
    j_dt = p.wheel_total_inertia / dt
    b = p.viscous_friction
    w = (j_dt * speed + k1 * volts) / (j_dt + k1 * ke_g + b)
    if abs(volts - ke_g * w) > p.current_limit * p.armature_resistance:
        tau = math.copysign(p.gear_ratio * p.gear_efficiency * k * p.current_limit, volts - ke_g * w)
        w = (j_dt * speed + tau) / (j_dt + b)
    return w


def simulate(p: ChairParams, run: Run) -> np.ndarray:
    """The wheels' angles (n x 2) at ``run``'s ticks, from rest at its first, driven by
    its duty: on the floor the plant itself, on blocks ``block_wheel_step``."""
    schedule = run.schedule()
    volts_per_duty = (p.battery_voltage or p.supply_voltage) / 255.0
    out = np.zeros((len(run.millis), 2))
    if not run.blocks:
        plant = Plant(p)
        for n, dl, dr, i in schedule:
            plant.set_drive(abs(int(dl)), int(dl >= 0), abs(int(dr)), int(dr >= 0))
            plant.advance(n, DT)
            if i >= 0:
                out[i + 1] = plant.left.angle, plant.right.angle
        return out
    # the kernel's wheel step, inlined (a call per step costs more than the step)
    k = p.motor_constant
    ke_g = k * p.gear_ratio
    k1 = p.gear_ratio * p.gear_efficiency * k / p.armature_resistance
    j_dt = p.wheel_total_inertia / DT
    b = p.viscous_friction
    limit_v = p.current_limit * p.armature_resistance
    tau_max = p.gear_ratio * p.gear_efficiency * k * p.current_limit
    free = j_dt + k1 * ke_g + b
    held = j_dt + b
    for side in (0, 1):
        w = theta = 0.0
        for n, dl, dr, i in schedule:
            volts = volts_per_duty * (dl if side == 0 else dr)
            drive = k1 * volts
            for _ in range(n):
                nxt = (j_dt * w + drive) / free
                if abs(volts - ke_g * nxt) > limit_v:
                    nxt = (j_dt * w + math.copysign(tau_max, volts - ke_g * nxt)) / held
                w = nxt
                theta += w * DT
            if i >= 0:
                out[i + 1, side] = theta
    return out


def with_motor_constant(p: ChairParams, k: float) -> ChairParams:
    """``p`` with the ``top_wheel_speed`` that makes its ``motor_constant`` ``k``.
    ``ChairParams.motor_constant`` solves ``V = k G w + R load / (k G eta)`` for ``k`` at
    the top speed ``w``, the load ``L0 + b w`` per wheel (rolling resistance, the
    casters' share, viscous friction); for a given ``k`` that is linear in ``w``:
    ``w = (V k - R L0 / (G eta)) / (G k^2 + R b / (G eta))``."""
    g, eta, res = p.gear_ratio, p.gear_efficiency, p.armature_resistance
    static = (p.rolling_resistance * p.drive_wheel_load
              + p.caster_rolling_resistance * p.caster_load) * p.wheel_radius
    top = ((p.supply_voltage * k - res * static / (g * eta))
           / (g * k * k + res * p.viscous_friction / (g * eta)))
    if not top > 0:
        raise ValueError(f"no top speed gives the motor constant {k}: too small for the loads")
    return dataclasses.replace(p, top_wheel_speed=float(top))


def apply(base: ChairParams, values: dict[str, float]) -> ChairParams:
    """``base`` with the ``FITTED`` figures of ``values``."""
    fields = {n: v for n, v in values.items() if n != "motor_constant"}
    p = dataclasses.replace(base, **fields)                     # type: ignore[arg-type]
    if "motor_constant" in values:
        p = with_motor_constant(p, values["motor_constant"])
    return p


def value(p: ChairParams, name: str) -> float:
    """A ``FITTED`` figure of ``p``."""
    return float(getattr(p, name))


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


def residuals(p: ChairParams, runs: Sequence[Run]) -> np.ndarray:
    """Simulated less measured mean wheel speeds over every tick interval of every run
    (rad/s), flattened; 0 where ``Run.weights`` leaves an interval out."""
    out = []
    for run in runs:
        sim = simulate(p, run)
        dt = np.diff(run.millis)[:, None] / 1000.0
        err = (np.diff(sim, axis=0) - np.diff(run.angle, axis=0)) / dt * run.weights()[:, None]
        out.append(err.ravel())
    return np.concatenate(out)


def rms(p: ChairParams, run: Run) -> float:
    """The RMS of ``residuals`` for one run (rad/s)."""
    return float(np.sqrt(np.mean(residuals(p, [run]) ** 2)))


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


def _uncertainty_scale(runs: Sequence[Run], fun: np.ndarray, counts_per_rev: int) -> float:
    """The variance that scales ``(J^T J)^-1`` into the figures' covariance: the
    residuals' own (robustly, from their median absolute deviation), no less than the
    counts' quantisation gives (one count at each end of a tick interval:
    ``2 q^2 / 12`` over the interval squared), and times ``(1 + r) / (1 - r)`` for the
    residuals' correlation ``r`` from one tick to the next: residuals that run in
    streaks (a model the data does not quite fit) carry fewer independent errors than
    their number."""
    used = fun[fun != 0.0]
    if used.size < 3:
        return math.inf
    mad = float(np.median(np.abs(used - np.median(used))))
    tick = float(np.median([r.tick_ms for r in runs])) / 1000.0
    var = max((1.4826 * mad) ** 2, (2.0 * math.pi / counts_per_rev / tick) ** 2 / 6.0)
    clipped = np.clip(fun, -3 * ROBUST_SCALE, 3 * ROBUST_SCALE)
    pairs, lagged, total = 0.0, 0.0, 0.0
    at = 0
    for run in runs:
        n = len(run.millis) - 1
        block = clipped[at:at + 2 * n].reshape(n, 2)
        at += 2 * n
        lagged += float(np.sum(block[1:] * block[:-1]))
        total += float(np.sum(block * block))
        pairs += n
    r = min(max(lagged / total, 0.0), 0.98) if total > 0 else 0.0
    return var * (1.0 + r) / (1.0 - r)


def _standard_errors(jac: np.ndarray, s2: float) -> list[float]:
    """Standard errors of the fitted (log) figures: ``sqrt(diag(s2 (J^T J)^-1))``; inf for
    a figure the residuals do not depend on (a zero column, or one the others span)."""
    norms = np.linalg.norm(jac, axis=0)
    if not norms.max() > 0:
        return [math.inf] * jac.shape[1]
    if not np.all(norms > 1e-9 * float(norms.max())):
        return _with_dead_columns(jac, s2, norms)
    scaled = jac / norms
    try:
        cov = np.linalg.inv(scaled.T @ scaled)
    except np.linalg.LinAlgError:
        return [math.inf] * jac.shape[1]
    return [math.sqrt(max(cov[i, i], 0.0) * s2) / norms[i] if cov[i, i] < 1e12 else math.inf
            for i in range(jac.shape[1])]


def _with_dead_columns(jac: np.ndarray, s2: float, norms: np.ndarray) -> list[float]:
    """``_standard_errors`` when some columns are zero: those inf, the rest on their own."""
    live = norms > 1e-9 * float(norms.max())
    out = [math.inf] * jac.shape[1]
    if live.any():
        for i, s in zip(np.flatnonzero(live), _standard_errors(jac[:, live], s2), strict=True):
            out[int(i)] = s
    return out


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


def degraded(run: Run, rng: np.random.Generator, *, quantum: int = 1, counts_per_rev: int | None = None,
             late: float = 0.0, late_ms: int = 2, drop: float = 0.0) -> Run:
    """``run`` as a poorer recording would give it: the counts floored to multiples of
    ``quantum`` (a coarser encoder); a share ``late`` of the ticks stamped up to
    ``late_ms`` ms after their counts were latched (a stamp that disagrees with its
    counts: the board's own lines cannot, as ``millis`` and the counts are taken in
    the same tick, but a logger that stamps lines as they arrive would); a share
    ``drop`` of the ticks lost (not the first)."""
    cpr = counts_per_rev or ChairParams().counts_per_rev
    step = 2.0 * math.pi * quantum / cpr
    angle = np.floor(np.round(run.angle / (2.0 * math.pi / cpr)) / quantum) * step
    millis = run.millis.copy()
    shifted = rng.random(len(millis)) < late
    shifted[0] = False
    millis[shifted] += rng.integers(1, late_ms + 1, size=int(shifted.sum()))
    keep = rng.random(len(millis)) >= drop
    keep[0] = True
    keep &= np.concatenate([[True], np.diff(millis) > 0])     # a late stamp may pass the next
    millis, duty, angle = millis[keep], run.duty[keep], angle[keep]
    return Run(millis=millis, duty=duty, angle=angle, blocks=run.blocks, name=run.name)
