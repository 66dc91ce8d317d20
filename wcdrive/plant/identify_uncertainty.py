"""The standard uncertainties of plant identification's fitted figures:
``_uncertainty_scale`` is the variance that scales the fit's ``(J^T J)^-1`` into the
figures' covariance, and ``_standard_errors`` the figures' standard errors from the
Jacobian at that variance (inf for a figure the residuals do not depend on).

The residuals' own scatter alone would promise too much: it is taken robustly (from
the median absolute deviation), no smaller than the counts' quantisation gives, and
widened by how much the residuals run in streaks: residuals that do (a model the data
does not quite fit) carry fewer independent errors than their number.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wcdrive.plant.identify_model import ROBUST_SCALE
from wcdrive.plant.identify_run import Run


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
