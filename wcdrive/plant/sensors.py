"""What the chair's sensors report: quadrature encoder counts and a z-axis gyro."""

from __future__ import annotations

import math

import numpy as np

from wcdrive.plant.params import ChairParams
from wcdrive.protocol.spec import real


def encoder_counts(angle_left: float, angle_right: float, cpr: int = round(real("CPR"))) -> tuple[int, int]:
    """Counts the firmware's decoders hold for these wheel angles (rad, forward +).
    The left encoder is mounted mirrored, so it counts down going forward."""
    scale = cpr / (2.0 * math.pi)
    return math.floor(-angle_left * scale), math.floor(angle_right * scale)


class Gyro:
    """A BMI085-like z-axis gyro: samples at ``gyro_rate_hz`` with white noise and a
    bias that drifts as a random walk. Deterministic for a given seed."""

    def __init__(self, params: ChairParams, seed: int = 0) -> None:
        self.period = 1.0 / params.gyro_rate_hz
        self._rng = np.random.default_rng(seed)
        dps = math.pi / 180.0
        self.noise = params.gyro_noise_dps * dps
        self.bias = float(self._rng.normal(0.0, params.gyro_bias_dps * dps))
        self.walk = params.gyro_bias_walk_dps_per_sqrt_s * dps
        self.next_time = 0.0
        self.times: list[float] = []
        self.rates: list[float] = []

    def sample(self, time: float, true_rate: float) -> None:
        """Takes every sample due by ``time`` at the current true yaw rate."""
        while self.next_time <= time + 1e-12:
            self.bias += self.walk * math.sqrt(self.period) * float(self._rng.standard_normal())
            self.times.append(self.next_time)
            self.rates.append(true_rate + self.bias + self.noise * float(self._rng.standard_normal()))
            self.next_time += self.period

    def sample_steps(self, t0: float, dt: float, rates: np.ndarray) -> None:
        """Every sample due by the end of ``len(rates)`` plant steps of ``dt`` from
        ``t0``, each at the true yaw rate of the step it falls in (``rates``): bit for
        bit the samples ``sample`` takes one at a time, with the random draws of the
        whole batch taken at once (``standard_normal(2 n)`` is the same stream)."""
        steps = len(rates)
        end = t0 + dt * steps + 1e-12
        t = self.next_time
        if steps <= 0 or t > end:
            return
        period = self.period
        due: list[float] = []
        while t <= end:
            due.append(t)
            t += period
        draws = self._rng.standard_normal(2 * len(due)).tolist()
        walk = self.walk * math.sqrt(period)
        noise, bias, last = self.noise, self.bias, steps - 1
        true = rates.tolist()
        out = self.rates
        for i, ts in enumerate(due):
            bias += walk * draws[2 * i]
            k = int((ts - t0) / dt - 1e-9)
            out.append(true[min(last, max(0, k))] + bias + noise * draws[2 * i + 1])
        self.times.extend(due)
        self.bias = bias
        self.next_time = t
