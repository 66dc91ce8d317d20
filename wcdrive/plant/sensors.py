"""What the chair's sensors report: quadrature encoder counts and a z-axis gyro."""

from __future__ import annotations

import ctypes
import math

import numpy as np

from wcdrive._util.history import History
from wcdrive.plant.chair import load_kernel
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
    board that runs for hours).

    Its random draws come from a buffer filled ahead in batches
    (``standard_normal(n)`` is the same stream as n single draws), so ``sample`` and
    ``sample_steps`` give the same samples whichever is called, bit for bit."""

    def __init__(self, params: ChairParams, seed: int = 0, history: int | None = None, *,
                 use_kernel: bool = True) -> None:
        self.period = 1.0 / params.gyro_rate_hz
        self._rng = np.random.default_rng(seed)
        dps = math.pi / 180.0
        #: the rate noise, deg/s rms (``noise`` in rad/s)
        self.noise_dps = params.gyro_noise_dps
        self.noise = params.gyro_noise_dps * dps
        self.bias = float(self._rng.normal(0.0, params.gyro_bias_dps * dps))
        self.walk = params.gyro_bias_walk_dps_per_sqrt_s * dps
        self.next_time = 0.0
        self.times: list[float] = [] if history is None else History(maxlen=history)
        self.rates: list[float] = [] if history is None else History(maxlen=history)
        self._draws = np.empty(0)
        self._used = 0
        self._kernel = load_kernel() if use_kernel else None
        #: gyro_samples' arguments: next time, bias, end, t0, dt, period, walk step, noise
        self._args = (ctypes.c_double * 8)()
        self._args_at = ctypes.addressof(self._args)
        self._out_times = self._out_rates = np.empty(0)
        self._out_at = (0, 0)
        self._draws_at = 0

    @property
    def samples_taken(self) -> int:
        """How many samples the gyro has taken (those ``times`` keeps and those it
        dropped to keep its ``history``)."""
        times = self.times
        return (times.dropped if isinstance(times, History) else 0) + len(times)

    def _reserve(self, count: int) -> None:
        """At least ``count`` unused draws in the buffer."""
        if self._used + count > self._draws.size:
            fresh = self._rng.standard_normal(max(count, _DRAW_BATCH))
            self._draws = np.concatenate((self._draws[self._used:], fresh))
            self._draws_at = _address(self._draws)
            self._used = 0

    def _draw(self) -> float:
        self._reserve(1)
        self._used += 1
        return float(self._draws[self._used - 1])

    def sample(self, time: float, true_rate: float) -> None:
        """Takes every sample due by ``time`` at the current true yaw rate."""
        while self.next_time <= time + 1e-12:
            self.bias += self.walk * math.sqrt(self.period) * self._draw()
            self.times.append(self.next_time)
            self.rates.append(true_rate + self.bias + self.noise * self._draw())
            self.next_time += self.period

    def sample_steps(self, t0: float, dt: float, rates: np.ndarray, rates_at: int | None = None) -> None:
        """Every sample due by the end of ``len(rates)`` plant steps of ``dt`` from
        ``t0``, each at the true yaw rate of the step it falls in (``rates``): bit for
        bit what ``sample`` takes one sample at a time (the C kernel's
        ``gyro_samples``, or the same lines here without it). ``rates_at``: the address
        of ``rates``'s data, when the caller knows it is a C-contiguous float64 array
        (the plant's own buffer)."""
        steps = len(rates)
        end = t0 + dt * steps + 1e-12
        if steps <= 0 or self.next_time > end:
            return
        if self._kernel is not None:
            if rates_at is None:
                if not (rates.flags.c_contiguous and rates.dtype == np.float64):
                    rates = np.ascontiguousarray(rates, dtype=np.float64)
                rates_at = _address(rates)
            args_at, draws_at, most, times_at, values_at = self.kernel_arguments(t0, steps, dt)
            self._args[2], self._args[3], self._args[4] = end, t0, dt
            self.kernel_took(self._kernel.gyro_samples(steps, args_at, rates_at, draws_at, most, times_at,
                                                       values_at))
            return
        most = int((end - self.next_time) / self.period) + 2
        self._reserve(2 * most)
        walk = self.walk * math.sqrt(self.period)
        true = rates.tolist()
        t, bias, used, draws = self.next_time, self.bias, self._used, self._draws
        while t <= end:
            bias += walk * float(draws[used])
            k = min(steps - 1, max(0, int((t - t0) / dt - 1e-9)))
            self.times.append(t)
            self.rates.append(true[k] + bias + self.noise * float(draws[used + 1]))
            used += 2
            t += self.period
        self.next_time, self.bias, self._used = t, bias, used

    # ---- the plant's kernel call (wcdrive.plant.chair.KernelSampler) -------------------
    @property
    def kernel_ready(self) -> bool:
        """Whether the C kernel takes the samples (``Plant.advance_batch``)."""
        return self._kernel is not None

    def kernel_arguments(self, t0: float, steps: int, dt: float) -> tuple[int, int, int, int, int]:
        """The kernel's arguments for the samples of ``steps`` steps of ``dt`` from
        ``t0`` (``KernelSampler``): the parameters' address (next time, bias, then the
        end, t0 and dt the caller or the kernel fills in, period, walk step, noise), the
        next draw's, the most samples, the output buffers'."""
        end = t0 + dt * steps + 1e-12
        most = max(0, int((end - self.next_time) / self.period) + 2)
        self._reserve(2 * most)
        if self._out_times.size < most:
            self._out_times, self._out_rates = np.empty(max(most, 64)), np.empty(max(most, 64))
            self._out_at = (_address(self._out_times), _address(self._out_rates))
        args = self._args
        args[0], args[1] = self.next_time, self.bias
        args[5], args[6], args[7] = self.period, self.walk * math.sqrt(self.period), self.noise
        return self._args_at, self._draws_at + 8 * self._used, most, self._out_at[0], self._out_at[1]

    def kernel_took(self, count: int) -> None:
        """The kernel took ``count`` samples: they join ``times`` and ``rates``."""
        args = self._args
        self._used += 2 * count
        self.next_time, self.bias = args[0], args[1]
        if count:
            self.times.extend(self._out_times[:count].tolist())
            self.rates.extend(self._out_rates[:count].tolist())


#: Random draws the gyro takes from its generator at a time.
_DRAW_BATCH = 4096


def _address(a: np.ndarray) -> int:
    return int(a.__array_interface__["data"][0])
