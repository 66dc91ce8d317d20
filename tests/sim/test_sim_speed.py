"""The simulation at 1000x: what was made faster gives the same bits.

* The event-driven ``PortLoop.run_until`` against its reference path (``stepped=True``,
  every Timer0 overflow in turn, as the loop was before): every bundled scenario through
  ``wcdrive.sim.runner`` on both, compared byte for byte (every line the board sent with
  its cycle, the firmware's whole state after every tick, the plant's and the gyro's
  outputs, every figure), and random byte streams, faults, resets and chunkings
  (hypothesis) straight on the loop. What both paths share is held to the outputs
  recorded before the simulation was made faster (``tests/data/sim_digests.json``, nine scenarios).
* ``Gyro.sample_steps`` against ``Gyro.sample`` one sample at a time.
* ``WheelOdometry.integrate`` (the covariance propagated when read) against ``update``.
* ``benchmarks/sim_speed.py --quick`` runs and prints its table.

Each test can fail: ``test_the_comparison_sees_a_one_overflow_slip`` shows it for the
loop; docs/benchmarks.md lists the mutants that turned the rest red.
"""

from __future__ import annotations

import dataclasses
import functools
import gc
import json
import math
import subprocess
import sys
import types
import typing
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tests.support.sim_digest import FIELDS, RECORDED, digest, fields
from wcdrive.avr.timer0 import OVERFLOW_CYCLES
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.firmware.eeprom import BLOCK_BYTES
from wcdrive.firmware.final_control import Firmware
from wcdrive.host.odometry import OdometryParams, WheelOdometry
from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.plant.faults import Fault
from wcdrive.plant.rosmap import OccupancyGrid
from wcdrive.protocol.codec import encode_cmdvel, encode_wheel
from wcdrive.sim import runner
from wcdrive.sim.scenario import bundled, load

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = [p.stem for p in bundled()]


def _signature(monkeypatch: pytest.MonkeyPatch, name: str, stepped: bool
               ) -> tuple[dict[str, object], runner.SimResult]:
    """Everything a port run of scenario ``name`` produces, the firmware's state after
    every tick included, with the loop on one path or the other."""
    states: list[tuple] = []
    tick = Firmware.tick

    def logged_tick(self: Firmware, *args, **kwargs) -> bytes:
        out = tick(self, *args, **kwargs)
        states.append(dataclasses.astuple(self.state))
        return out

    monkeypatch.setattr(Firmware, "tick", logged_tick)
    monkeypatch.setattr(runner, "PortLoop", functools.partial(PortLoop, stepped=stepped))
    result = runner.run(load(name))
    monkeypatch.undo()
    out: dict[str, object] = {"states": states}
    for key, value in fields(result).items():
        if isinstance(value, OccupancyGrid):                # a map's cells, as an array
            value = np.concatenate((value.data.reshape(-1), np.array((*value.origin, value.resolution))))
        out[key] = value.tobytes() + str(value.shape).encode() if isinstance(value, np.ndarray) else value
    metrics = result.metrics()
    metrics.pop("real_time_factor")
    out["metrics"] = repr(metrics)
    return out, result


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_scenario_runs_the_same_on_the_event_loop(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    stepped, _ = _signature(monkeypatch, name, stepped=True)
    event, result = _signature(monkeypatch, name, stepped=False)
    assert len(stepped["states"]) == len(event["states"]) > 0          # type: ignore[arg-type]
    assert stepped.keys() == event.keys()
    differing = [key for key in stepped if stepped[key] != event[key]]
    assert not differing, f"{name}: {differing}"
    if name in RECORDED:
        # what both paths share (the plant's batches, the gyro, the wire, the odometry),
        # against the outputs recorded before the speed-up (tests/support/sim_digest.py)
        recorded = json.loads((ROOT / "tests" / "data" / "sim_digests.json").read_text())[name]
        now = digest(result)
        assert now.keys() == recorded.keys()
        changed = [key for key in now if now[key] != recorded[key]]
        assert not changed, (f"{name}: {changed} differ from the recorded outputs; re-record only "
                             "for a change on purpose (tests/support/sim_digest.py)")


def test_the_digest_names_every_field_of_a_result() -> None:
    """``FIELDS`` (the digest's names) reaches every field of ``SimResult`` and of its
    records but the wall time, each once: a field added to a record is digested."""
    leaves = set()
    for name, hint in typing.get_type_hints(runner.SimResult).items():
        options = typing.get_args(hint) if isinstance(hint, types.UnionType) else (hint,)   # a record or None
        record = next((t for t in options if dataclasses.is_dataclass(t)), None)
        if record is None:
            leaves.add(name)
        else:
            leaves.update(f"{name}.{f.name}" for f in dataclasses.fields(record))
    paths = list(FIELDS.values())
    assert len(set(paths)) == len(paths)
    assert leaves - {"wall_time"} == set(paths) - {"ticks"}


def test_a_backend_object_runs_as_its_name() -> None:
    sc = load("fault_reset")
    assert digest(runner.run(sc, backend=runner.PortBackend())) == digest(runner.run(sc, backend="port"))


# ---- the loop alone, on random inputs ---------------------------------------------------
@dataclasses.dataclass
class _Run:
    output: list[tuple[int, bytes]]
    states: list[tuple]
    ticks: list[int]
    end: tuple


def _drive(stepped: bool, sends: list[tuple[int, bytes]], chunks: list[int], faults: list[Fault],
           resets: list[int], replace_fw: int | None) -> _Run:
    """A loop on one path: bytes sent at their cycles, ``run_until`` in the given chunks
    (as the live board runs it), ``reset()`` calls and a firmware replaced mid-run (as
    tests/host/test_session.py does, out of setup() at the present millis())."""
    plant = Plant(ChairParams())
    loop = PortLoop(plant, Gyro(ChairParams(), 3), faults=faults, stepped=stepped)
    states: list[tuple] = []
    ticks: list[int] = []

    def on_tick(_: float) -> None:
        states.append(dataclasses.astuple(loop.fw.state))
        ticks.append(loop.last_tick_cycle or 0)

    pending = sorted(sends)
    pending_resets = sorted(resets)
    cycle = 0
    for end in chunks:
        while pending and pending[0][0] <= cycle:
            loop.send(pending.pop(0)[1])
        while pending_resets and pending_resets[0] <= cycle:
            pending_resets.pop(0)
            loop.reset()
        if replace_fw is not None and replace_fw <= cycle:
            loop.fw = Firmware(boot_millis=loop.timer.millis)
            loop.output.append((loop.cycle, loop.fw.boot_output()))
            replace_fw = None
        loop.run_until(end, on_tick)
        cycle = end
    gyro = loop.gyro
    assert gyro is not None
    end_state = (loop.timer.millis, loop.timer.fract, loop.cycle, loop.encoder_counts(),
                 loop.encoder_states(), plant.pose, plant.left.angle, plant.right.angle,
                 tuple(gyro.times), tuple(gyro.rates), gyro.bias)
    return _Run(loop.take_output(), states, ticks, end_state)


_COMMANDS = st.sampled_from([
    encode_cmdvel(0.5, 0.0), encode_cmdvel(0.3, 0.4), encode_cmdvel(-0.4, 0.0), encode_cmdvel(0.0, 0.0),
    encode_wheel(3.0, 2.0), b"reset\n", b"stop\n", b"x:0.5,t:", b"garbage,", b"\n",
    b"save\n", b"defaults\n", b"set:kp_l=1.5\n",
])
_FAULTS = st.sampled_from([
    [], [Fault("reset", 0.37)], [Fault("encoder_cut", 0.3, "left", 0.4)],
    [Fault("encoder_noise", 0.3, "right", 0.05, 200_000.0)], [Fault("wheel_locked", 0.25, "both", 0.3)],
    [Fault("encoder_reversed", 0.2, "right")], [Fault("motor_dead", 0.4, "left")],
])


@settings(max_examples=150, deadline=None)      # about 1 ms a run: cheap to search widely
@given(sends=st.lists(st.tuples(st.integers(0, round(1.2 * F_CPU)), _COMMANDS), max_size=25),
       cuts=st.lists(st.integers(1, round(1.2 * F_CPU)), max_size=30),
       faults=_FAULTS,
       resets=st.lists(st.integers(1, round(1.2 * F_CPU)), max_size=2),
       replace_fw=st.none() | st.integers(1, round(1.2 * F_CPU)))
# a firmware put in while a save is written, then a save on it (the event path kept the
# old write's time for the new save's interrupts: a byte more written by the first tick)
@example(sends=[(0, b"save\n"), (1, b"save\n")], cuts=[], faults=[], resets=[], replace_fw=1)
def test_the_event_loop_matches_the_stepped_loop_on_random_inputs(sends, cuts, faults, resets,
                                                                   replace_fw) -> None:
    # chunk ends at random cycles, at overflows exactly and a cycle either side of one
    chunks = sorted({*cuts, round(1.2 * F_CPU), 25_461 + 10 * OVERFLOW_CYCLES,
                     25_461 + 30 * OVERFLOW_CYCLES - 1, 25_461 + 31 * OVERFLOW_CYCLES + 1})
    a = _drive(True, sends, chunks, faults, resets, replace_fw)
    b = _drive(False, sends, chunks, faults, resets, replace_fw)
    assert a.ticks == b.ticks
    assert a.output == b.output
    assert a.states == b.states
    assert a.end == b.end


@settings(max_examples=60, deadline=None)
@given(ops=st.lists(st.tuples(st.sampled_from(["send", "take", "drop", "take_exact", "drop_exact"]),
                              st.integers(0, 40_000),
                              st.binary(min_size=0, max_size=20)), max_size=60))
def test_the_wire_keeps_bytes_as_the_byte_queue_did(ops) -> None:
    """``port_loop._Wire`` (runs of bytes) against the queue of (arrival, byte) that
    ``PortLoop`` kept before its event-driven path."""
    from collections import deque

    from wcdrive.avr.uart import UART_BYTE_CYCLES
    from wcdrive.boards.port_loop import _Wire

    wire, queue = _Wire(), deque()                  # type: ignore[var-annotated]
    now = free = 0
    for op, step, data in ops:
        now += step
        if op.endswith("_exact") and queue:          # right at the next byte's arrival
            now = max(now - step, queue[0][0] + (step % 3) - 1)
            op = op[:-6]
        if op == "send":
            start = max(now, free)
            if data:
                wire.push(start, data)
            for i, b in enumerate(data):
                queue.append((start + (i + 1) * UART_BYTE_CYCLES, b))
            free = start + len(data) * UART_BYTE_CYCLES
        elif op == "take":
            want = bytearray()
            while queue and queue[0][0] <= now:
                want.append(queue.popleft()[1])
            assert wire.take(now) == bytes(want)
        else:
            while queue and queue[0][0] < now:
                queue.popleft()
            wire.drop_before(now)
        assert bool(wire) == bool(queue)
        if queue:
            assert wire.next_arrival() == queue[0][0]


def test_the_comparison_sees_a_one_overflow_slip(monkeypatch: pytest.MonkeyPatch) -> None:
    """A mutant event loop whose ``millis()`` jump is one overflow short (the bytes
    read and the tick run at the right cycle, with ``millis()`` one overflow behind):
    the comparison above turns red."""
    sends = [(round(0.02 * F_CPU) + k * round(0.1 * F_CPU), encode_cmdvel(0.5, 0.1)) for k in range(8)]
    chunks = [round(0.9 * F_CPU)]
    good = _drive(False, sends, chunks, [], [], None)
    assert good.output == _drive(True, sends, chunks, [], [], None).output
    jump = PortLoop._jump_timer
    monkeypatch.setattr(PortLoop, "_jump_timer", lambda self, n: jump(self, n - 1 if n > 1 else n))
    bad = _drive(False, sends, chunks, [], [], None)
    assert bad.output != good.output or bad.states != good.states


def test_the_event_loop_asks_due_rarely() -> None:
    """The point of the event loop: ``Firmware.due`` is asked a few times a tick, not at
    every overflow (about 49 a tick on the stepped path)."""
    calls = {True: 0, False: 0}
    for stepped in (True, False):
        fw = Firmware()
        due = fw.due

        def counted(now: int, stepped: bool = stepped, due=due) -> bool:
            calls[stepped] += 1
            return due(now)

        fw.due = counted                   # type: ignore[method-assign]
        loop = PortLoop(Plant(), firmware=fw, stepped=stepped)
        for k in range(20):
            loop.send(encode_cmdvel(0.4, 0.0), at=round((0.02 + 0.1 * k) * F_CPU))
        loop.run_until(round(2.0 * F_CPU))
    assert calls[True] > 1900
    assert calls[False] < 0.2 * calls[True]


# ---- the gyro and the odometry --------------------------------------------------------
class _GyroBefore:
    """``Gyro`` as it was before the batched kernel (one scalar draw at a time), sampled as
    ``port_loop.advance`` sampled it: ``sample`` per sample."""

    def __init__(self, params: ChairParams, seed: int) -> None:
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
        while self.next_time <= time + 1e-12:
            self.bias += self.walk * math.sqrt(self.period) * float(self._rng.standard_normal())
            self.times.append(self.next_time)
            self.rates.append(true_rate + self.bias + self.noise * float(self._rng.standard_normal()))
            self.next_time += self.period

    def advance(self, t0: float, dt: float, rates: np.ndarray) -> None:
        steps = len(rates)
        end = t0 + dt * steps
        while self.next_time <= end + 1e-12:
            k = min(steps - 1, max(0, int((self.next_time - t0) / dt - 1e-9)))
            self.sample(self.next_time, float(rates[k]))


@pytest.mark.parametrize("use_kernel", [True, False])
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rate_hz=st.sampled_from([100.0, 400.0, 1000.0, 1600.0, 733.0]),
       batches=st.lists(st.integers(1, 3000), min_size=1, max_size=12),
       dt=st.sampled_from([0.001, 0.0005, 0.002, 0.00037]), singles=st.integers(0, 3))
def test_gyro_batches_are_the_samples_one_at_a_time(use_kernel: bool, seed: int, rate_hz: float,
                                                    batches: list[int], dt: float, singles: int) -> None:
    params = ChairParams(gyro_rate_hz=rate_hz)
    before, now = _GyroBefore(params, seed), Gyro(params, seed, use_kernel=use_kernel)
    rng = np.random.default_rng(seed)
    t0 = 0.0
    for n in batches:
        rates = rng.normal(0.0, 1.0, n)
        before.advance(t0, dt, rates)
        now.sample_steps(t0, dt, rates)
        t0 = t0 + dt * n
        for _ in range(singles):               # sample() and sample_steps() share the draws
            t0 += dt
            before.sample(t0, 0.25)
            now.sample(t0, 0.25)
    assert before.times == now.times and before.rates == now.rates
    assert before.bias == now.bias and before.next_time == now.next_time
    assert all(type(v) is float for v in now.rates[:5] + now.times[:5])


def test_odometry_integrate_gives_update_s_covariance_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    op = OdometryParams()
    for method in ("position", "velocity"):
        eager, lazy = WheelOdometry(op, method), WheelOdometry(op, method)
        left = right = 0
        for k in range(5000):
            left += int(rng.integers(-400, 100))
            right += int(rng.integers(-100, 400))
            eager.update(0.05 * k, left, right)
            lazy.integrate(0.05 * k, left, right)
            if k % 997 == 0 or k == 4999:
                a, b = eager.estimate(0.05 * k), lazy.estimate(0.05 * k)
                assert np.array_equal(a.pose_covariance, b.pose_covariance)
                assert np.array_equal(a.twist_covariance, b.twist_covariance)
                assert (a.pose, a.linear, a.angular) == (b.pose, b.linear, b.angular)
        assert eager.estimate(1.0).pose_covariance[0, 0] > 0


def test_the_motion_log_rows_are_the_reference_s() -> None:
    """The kernel writes the whole motion-log row; the Python path (the reference)
    writes time and volts with numpy. Same bits."""
    plants = [Plant(use_kernel=True), Plant(use_kernel=False)]
    if not plants[0].uses_kernel:
        pytest.skip("no C compiler")
    for p in plants:
        p.start_motion_log()
        p.set_drive(120, 1, 90, 0)
        p.advance(37, 0.001)
        p.set_drive(200, 1, 200, 1)
        p.advance(50, 0.001)
    kernel, python = (p.take_motion_log() for p in plants)
    assert np.array_equal(kernel[:, [0, 4, 5]], python[:, [0, 4, 5]])
    assert np.allclose(kernel[:, 1:4], python[:, 1:4], rtol=1e-9, atol=1e-12)


def test_advance_batch_is_advance() -> None:
    """``Plant.advance_batch`` (buffers kept, the log written in place) against
    ``advance(record=True)``: the same angles, rates and motion log, bit for bit, across
    log chunks and with ``advance`` calls in between."""
    a, b = Plant(), Plant()
    for p in (a, b):
        p.start_motion_log()
    rng = np.random.default_rng(2)
    for k in range(400):
        n = int(rng.integers(1, 120))
        drive = [int(rng.integers(0, 256)), int(rng.integers(0, 2)), int(rng.integers(0, 256)),
                 int(rng.integers(0, 2))]
        a.set_drive(*drive)
        b.set_drive(*drive)
        want = a.advance(n, 0.001, record=True)
        assert want is not None
        if k % 7 == 3:
            got = b.advance(n, 0.001, record=True)
            assert got is not None
        else:
            got = b.advance_batch(n, 0.001, angles=k % 2 == 0)
        if k % 2 == 0 or k % 7 == 3:
            assert np.array_equal(want[0], got[0])
        assert np.array_equal(want[1], got[1])
        if k % 50 == 0:
            assert np.array_equal(a.take_motion_log(), b.take_motion_log())
    assert np.array_equal(a.take_motion_log(), b.take_motion_log())
    assert a.pose == b.pose


# ---- the benchmark's short mode ---------------------------------------------------------
def test_the_benchmark_short_mode_prints_its_table() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "sim_speed.py"), "--quick"],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert any(line.startswith("| square ") for line in lines)
    assert any("port + plant vs simavr + plant" in line for line in lines)
    row = next(line for line in lines if line.startswith("| square "))
    rtf = float(row.split("|")[2].replace(",", "").rstrip("x "))
    assert math.isfinite(rtf) and rtf > 10


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rate_hz=st.sampled_from([400.0, 1000.0, 733.0]),
       batches=st.lists(st.integers(1, 200), min_size=1, max_size=30),
       dt=st.sampled_from([0.001, 0.00037]))
def test_the_gyro_in_the_plant_s_kernel_call_is_sample_steps(seed: int, rate_hz: float, batches: list[int],
                                                             dt: float) -> None:
    """``Plant.advance_batch(sampler=gyro)`` (the samples taken in the plant's kernel
    call, as ``wcdrive sim`` does) against the plant's batch and then the Python
    ``Gyro.sample_steps`` (no kernel): the same samples, bias and next time, bit for bit."""
    params = ChairParams(gyro_rate_hz=rate_hz)
    fused_plant, plant = Plant(params), Plant(params)
    if not fused_plant.uses_kernel:
        pytest.skip("no C compiler")
    fused, alone = Gyro(params, seed), Gyro(params, seed, use_kernel=False)
    rng = np.random.default_rng(seed)
    for n in batches:
        left, right = (int(v) for v in rng.integers(0, 256, 2))
        for p in (fused_plant, plant):
            p.set_drive(left, 1, right, 0)
        fused_plant.advance_batch(n, dt, sampler=fused)
        t0 = plant.time
        _, rates = plant.advance_batch(n, dt)
        alone.sample_steps(t0, dt, rates)
    assert fused.times == alone.times and fused.rates == alone.rates
    assert fused.bias == alone.bias and fused.next_time == alone.next_time
    assert len(fused.times) >= sum(batches) * dt * rate_hz - 2


def test_a_run_leaves_no_cyclic_garbage_a_tick() -> None:
    """``runner.run`` pauses the cyclic garbage collector (``cyclic_gc_paused``): that
    is safe only if a run's cyclic garbage does not grow with its length. A 4 s and a
    100 s run leave the same few objects in cycles (the plant's pymunk space)."""
    left = []
    for name in ("fault_encoder_noise_200k", "fault_encoder_noise_200k", "corridor_100m"):
        gc.collect()
        gc.disable()
        try:
            runner.run(load(name))
            left.append(gc.collect())
        finally:
            gc.enable()
    assert left[2] <= left[1] + 5 and left[2] < 100, left
    assert gc.isenabled()
    with runner.cyclic_gc_paused():
        assert not gc.isenabled()
    assert gc.isenabled()


def test_runs_in_threads_share_the_collector_s_pause() -> None:
    """Two runs that overlap in two threads: the collector stays off until the last one
    ends, then comes back; a process that had it off keeps it off."""
    import threading

    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen = []

    def first() -> None:
        with runner.cyclic_gc_paused():
            first_in.set()
            second_in.wait(5)
        first_out.set()

    def second() -> None:
        first_in.wait(5)
        with runner.cyclic_gc_paused():
            second_in.set()
            first_out.wait(5)
            seen.append(gc.isenabled())          # the first run has ended, this one not
    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert seen == [False] and gc.isenabled()
    gc.disable()
    try:
        with runner.cyclic_gc_paused():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_an_eeprom_save_completes_on_the_event_loop() -> None:
    """``save`` writes its block byte by byte from the EEPROM-ready interrupt: the event
    loop polls it as the stepped loop does at every overflow, so the write ends and a
    second ``save`` a second later is taken (it answered ``ERR:busy`` before)."""
    sends = [(round(0.01 * F_CPU), b"save\n"), (round(1.0 * F_CPU), b"save\n")]
    chunks = [round(0.5 * F_CPU), round(1.5 * F_CPU)]
    a, b = _drive(True, sends, chunks, [], [], None), _drive(False, sends, chunks, [], [], None)
    assert a.output == b.output and a.states == b.states and a.end == b.end
    out = b"".join(data for _, data in b.output)
    assert b"ERR:busy" not in out
    last = dict(zip([f.name for f in dataclasses.fields(Firmware().state)], b.states[-1], strict=True))
    assert last["eeBusy"] == 0 and last["eeNext"] == BLOCK_BYTES


@pytest.mark.parametrize("ahead", [1, 2, 3])
def test_a_grid_a_ms_ahead_of_millis(ahead: int) -> None:
    """A firmware whose lastControlTime is a ms or two ahead of millis() (not due now,
    nor for 50 ms): the event loop ticks where the stepped loop does."""
    runs = []
    for stepped in (True, False):
        loop = PortLoop(Plant(), firmware=Firmware(boot_millis=ahead), stepped=stepped)
        loop.run_until(round(0.3 * F_CPU))
        runs.append([data for _, data in loop.take_output()])
    assert runs[0] == runs[1] and sum(data.startswith(b"ENC:") for data in runs[1]) >= 5
