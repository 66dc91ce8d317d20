"""What the chair's sensors report: quadrature encoder counts and a z-axis gyro."""

from __future__ import annotations

import math

import numpy as np

from wcdrive.history import History
from wcdrive.plant.params import ChairParams
from wcdrive.protocol.spec import real


def encoder_counts(angle_left: float, angle_right: float, cpr: int = round(real("CPR"))) -> tuple[int, int]:
    """Counts the firmware's decoders hold for these wheel angles (rad, forward +).
    The left encoder is mounted mirrored, so it counts down going forward."""
    scale = cpr / (2.0 * math.pi)
    return math.floor(-angle_left * scale), math.floor(angle_right * scale)


class Gyro:
    """A BMI085-like z-axis gyro: samples at ``gyro_rate_hz`` with white noise and a
    bias that drifts as a random walk. Deterministic for a given seed. ``times`` and
    ``rates`` keep every sample, or with ``history`` only the newest ``history`` (for a
    board that runs for hours)."""

    def __init__(self, params: ChairParams, seed: int = 0, history: int | None = None) -> None:
        self.period = 1.0 / params.gyro_rate_hz
        self._rng = np.random.default_rng(seed)
        dps = math.pi / 180.0
        self.noise = params.gyro_noise_dps * dps
        self.bias = float(self._rng.normal(0.0, params.gyro_bias_dps * dps))
        self.walk = params.gyro_bias_walk_dps_per_sqrt_s * dps
        self.next_time = 0.0
        self.times: list[float] = [] if history is None else History(maxlen=history)
        self.rates: list[float] = [] if history is None else History(maxlen=history)

    def sample(self, time: float, true_rate: float) -> None:
        """Takes every sample due by ``time`` at the current true yaw rate."""
        while self.next_time <= time + 1e-12:
            self.bias += self.walk * math.sqrt(self.period) * float(self._rng.standard_normal())
            self.times.append(self.next_time)
            self.rates.append(true_rate + self.bias + self.noise * float(self._rng.standard_normal()))
            self.next_time += self.period
