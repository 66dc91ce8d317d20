"""The C control tick (wcdrive/firmware/csrc/tick_fast.c) against the Python tick it
stands in for (``control.control_tick``, the reference): on random states and inputs
the same bytes and the same state bit for bit, or a refusal that changed nothing; on
whole scenarios the same runs. The differential suite holds the port, this path by
default, to the compiled firmware."""

from __future__ import annotations

import ast
import dataclasses
import math
import os
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tests.conftest import thorough
from wcdrive.avr.f32 import f32, from_bits
from wcdrive.firmware import constants as C
from wcdrive.firmware import final_control, tick_fast
from wcdrive.firmware.control import control_tick
from wcdrive.firmware.state import FLOAT_FIELDS, FirmwareState
from wcdrive.sim import runner, scenario

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(tick_fast.fast is None,
                                reason="the C tick did not build (a warning says why)")


def fast_tick(s: FirmwareState, now: int, *inputs: int) -> bytes | None:
    assert tick_fast.fast is not None
    return tick_fast.fast.tick(s, now, *inputs)


def python_tick(s: FirmwareState, now: int, *inputs: int) -> bytes:
    out = bytearray()
    control_tick(s, now, inputs[0], inputs[1], out, *inputs[2:])
    return bytes(out)


def as_bits(s: FirmwareState) -> dict[str, object]:
    """Every field, floats as their double's bits (so -0.0, NaN payloads and unrounded
    values count)."""
    return {k: struct.pack("<d", v) if isinstance(v, float) else v for k, v in s.as_dict().items()}


def agree(state: FirmwareState, now: int, inputs: tuple[int, ...]) -> bool:
    """C and Python from copies of ``state``: the same bytes and state, or a C refusal
    that left its copy as it was. Returns whether C computed the tick."""
    c_state, py_state = state.copy(), state.copy()
    sent = fast_tick(c_state, now, *inputs)
    if sent is None:
        assert as_bits(c_state) == as_bits(state), "a refused tick changed the state"
        return False
    want = python_tick(py_state, now, *inputs)
    assert sent == want
    assert as_bits(c_state) == as_bits(py_state)
    for name in FLOAT_FIELDS:           # and the same types
        assert type(getattr(c_state, name)) is type(getattr(py_state, name)), name
    return True


# ---- random states -------------------------------------------------------------------
ordinary = st.floats(-40.0, 40.0, width=32)
SPECIAL = [0.0, -0.0, 1e-40, -1e-40, 2.0**-126, 3e38, -3e38, math.inf, -math.inf, math.nan,
           from_bits(0xFFC01234), 0.1]            # 0.1: a double that is not a binary32
floats = st.one_of(ordinary, ordinary, ordinary, st.sampled_from(SPECIAL), st.floats(width=32))
u32 = st.integers(0, 2**32 - 1)
SMALL = {"pwmL": (0, 255), "pwmR": (0, 255), "dirL": (0, 1), "dirR": (0, 1), "mode": (-1, 3),
         "pivotPhase": (0, 2), "pivotTicksLeft": (0, 12), "stillTicks": (0, 255), "parked": (0, 1),
         "cmdSinceTick": (0, 1), "watchdogArmed": (0, 1), "emergencyStop": (0, 1), "tlmEnabled": (0, 1),
         "faultFlags": (0, 3), "stallTicksL": (0, 6), "stallTicksR": (0, 6), "reverseTicksL": (0, 4),
         "reverseTicksR": (0, 4), "runawayTicksL": (0, 6), "runawayTicksR": (0, 6),
         "effortTicksL": (0, 12), "effortTicksR": (0, 12), "effortPwmL": (0, 255),
         "effortPwmR": (0, 255), "estopLatched": (0, 1), "ppmLost": (0, 1), "txCredit": (0, 200),
         "stormTickL": (0, 1), "stormTickR": (0, 1), "errLinesThisTick": (0, 5), "feedbackForm": (0, 1),
         "neutralSeen": (0, 1), "neutralTicks": (0, 3), "notNeutralSent": (0, 1), "notNeutralPending": (0, 1),
         "notNeutralTicks": (0, 120), "neutralFault": (0, 1), "inhibitStable": (0, 3),
         "inhibitLatched": (0, 3), "inhibitCountL": (0, 2), "inhibitCountR": (0, 2),
         "inhibitPending": (0, 15),
         "inhibitOn": (0, 3), "thermalRollback": (0, 1), "thermalPending": (0, 3), "batteryLow": (0, 1),
         "batteryPending": (0, 3)}


@st.composite
def states(draw) -> tuple[FirmwareState, int, tuple[int, ...]]:
    s = FirmwareState()
    for name in FLOAT_FIELDS:
        if draw(st.booleans()):
            setattr(s, name, draw(floats))
    for name, (lo, hi) in SMALL.items():
        if draw(st.booleans()):
            setattr(s, name, draw(st.integers(lo, hi)))
    # the windings near the rollback's start too (110 deg C): the C tick's estimate and
    # its decline there
    for name in ("windingTempL", "windingTempR"):
        if draw(st.booleans()):
            setattr(s, name, draw(st.floats(100.0, 130.0, width=32)))
    # the supply near the low-battery threshold (23 V), read anywhere in the ADC's range
    if draw(st.booleans()):
        s.supplyVolts = draw(st.floats(20.0, 26.0, width=32))
    supply = draw(st.one_of(st.just(C.SUPPLY_NOMINAL_COUNTS), st.integers(700, 900), st.integers(0, 1023)))
    # the motors' currents: at rest, about the stall current (11 A: 90 counts from 512) either
    # way, or anywhere; and the stall clock running
    current = st.one_of(st.just(C.CURRENT_ZERO_COUNTS), st.integers(412, 612), st.integers(0, 1023))
    currents = (draw(current), draw(current))
    if draw(st.booleans()):
        s.stallTime = draw(st.floats(0.0, 16.0, width=32))
    # Waiting for neutral (a boot's default) the C tick declines: mostly a board that drives.
    s.needNeutral = draw(st.sampled_from((0, 0, 0, 1)))
    s.lastControlTime = draw(u32)
    s.lastTickTime = draw(st.one_of(st.just(s.lastControlTime), u32, st.none()))
    s.lastCmdTime = (s.lastControlTime - draw(st.integers(0, 2000))) & 0xFFFFFFFF
    s.prevEncL, s.prevEncR = draw(st.integers(-(2**31), 2**31 - 1)), draw(st.integers(-(2**31), 2**31 - 1))
    s.illTickL, s.illTickR = draw(u32), draw(u32)
    s.tickCount, s.lateTicks, s.txDropped = draw(u32), draw(u32), draw(u32)
    s.freeRam = draw(st.integers(0, 8192))
    now = (s.lastControlTime + draw(st.one_of(st.integers(49, 52), st.integers(0, 2**32 - 1)))) & 0xFFFFFFFF
    moved = st.one_of(st.integers(-3000, 3000), st.integers(-(2**33), 2**33))
    inputs = (s.prevEncL + draw(moved), s.prevEncR + draw(moved),
              (s.illTickL + draw(st.integers(0, 3))) & 0xFFFFFFFF,
              (s.illTickR + draw(st.integers(0, 3))) & 0xFFFFFFFF,
              draw(st.sampled_from((0, 0, 0, 1))), draw(st.sampled_from((0, 0, 0, 1))), draw(u32),
              draw(st.sampled_from((0, 0, 0, 0, 0, 1, 2, 3))), supply, *currents)
    return s, now, inputs


#: About 7 ms an example: the fast depth draws a quarter of the thorough one's.
@settings(max_examples=2000 if thorough() else 500)
@given(states())
@example((FirmwareState(lastControlTime=1000, targetL=2.0, targetR=2.0, needNeutral=0), 1050,
          (0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512)))
@example((FirmwareState(lastControlTime=1000, lastTickTime=1050, needNeutral=0), 1050,
          (5, 5, 0, 0, 0, 0, 0, 0, 819, 512, 512)))  # dt 0
# both wheels creeping (0 and 2 counts) at the stall current either way, and a failed sense
@example((FirmwareState(lastControlTime=1000, needNeutral=0, setpointL=2.0, targetL=2.0, setpointR=2.0,
                        targetR=2.0, pwmL=60, pwmR=60), 1050, (0, 2, 0, 0, 0, 0, 0, 0, 819, 603, 421)))
@example((FirmwareState(lastControlTime=1000, needNeutral=0, setpointL=2.0, targetL=2.0, setpointR=2.0,
                        targetR=2.0, pwmL=60, pwmR=60, stallTime=14.99), 1050,
          (-2, 0, 0, 0, 0, 0, 0, 0, 819, 603, 603)))
@example((FirmwareState(lastControlTime=1000, needNeutral=0), 1050, (0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 758)))
def test_the_c_tick_agrees_with_the_python_tick(case) -> None:
    state, now, inputs = case
    agree(state, now, inputs)


def test_random_ordinary_ticks_take_the_c_path() -> None:
    """Most ticks of a chair in motion are computed in C (else the checks above would
    pass on refusals alone), and all agree: 20,000 states along a driven trajectory (the
    first 5,000 of them at the fast depth), more than 3 in 4 of them in C. (The chair's
    neutral command has stood: a tick that waits for one is the Python tick's.)"""
    rng = np.random.default_rng(3)
    s = FirmwareState(lastControlTime=1000, tlmEnabled=1, needNeutral=0)
    taken = 0
    now, left, right = 1000, 0, 0
    states = 20_000 if thorough() else 5_000
    for k in range(states):
        if k % 40 == 0:
            s.targetL, s.targetR = (f32(float(x)) for x in rng.uniform(-4, 4, 2))
            s.cmdSinceTick = 1
        now = (now + 50) & 0xFFFFFFFF
        left += int(rng.integers(-400, 400))
        right += int(rng.integers(-400, 400))
        inputs = (left, right, 0, 0, 0, 0, 0, 0, C.SUPPLY_NOMINAL_COUNTS, C.CURRENT_ZERO_COUNTS,
                  C.CURRENT_ZERO_COUNTS)
        taken += agree(s, now, inputs)
        python_tick(s, now, *inputs)            # the trajectory goes on in Python
        s.faultFlags = 0                        # (random counts would latch faults,
        s.overspeedTicksL = s.overspeedTicksR = 0   # and overspeeds;
        s.needNeutral = 0                       # the watchdog's stops wait for a neutral command)
    assert taken > states * 3 // 4, taken


def test_a_fault_or_the_watchdog_goes_to_the_python_tick() -> None:
    """A tick that latches a fault or fires the watchdog is refused, the state as it was."""
    stalled = FirmwareState(lastControlTime=1000, setpointL=2.0, targetL=2.0, pwmL=200, dirL=C.HIGH,
                            stallTicksL=C.FAULT_STALL_TICKS - 1)
    assert fast_tick(stalled.copy(), 1050, 0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512) is None
    assert b"EVT:FAULT" in python_tick(stalled.copy(), 1050, 0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512)
    watched = FirmwareState(lastControlTime=1000, watchdogArmed=1, lastCmdTime=0, watchdogMs=500)
    assert fast_tick(watched.copy(), 1050, 0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512) is None
    assert b"EVT:WATCHDOG" in python_tick(watched.copy(), 1050, 0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512)


def test_an_unexpected_field_type_goes_to_the_python_tick() -> None:
    for name, value in (("targetL", 2), ("pwmL", 3.0), ("mode", True), ("tickCount", 2**70)):
        s = FirmwareState(lastControlTime=1000)
        setattr(s, name, value)
        assert fast_tick(s, 1050, 0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512) is None, name

    class Sub(FirmwareState):
        pass

    assert fast_tick(Sub(lastControlTime=1000), 1050, 0, 0, 0, 0, 0, 0, 0, 0, 819, 512, 512) is None


def test_the_firmware_ticks_in_c() -> None:
    """``Firmware.tick`` takes the C path; on a corridor run the ticks refused are the
    NEUTRAL_TICKS ticks that wait for the host's neutral command after the boot, the
    one whose watchdog fires at the end, the one whose hold starts once the chair has
    braked, and the one whose hold reference still follows the last of the coast."""
    assert final_control._fast_tick is tick_fast.fast.tick
    calls = refused = waiting = 0
    real = final_control._fast_tick

    def counting(*args):
        nonlocal calls, refused, waiting
        calls += 1
        waits = args[0].needNeutral
        sent = real(*args)
        refused += sent is None and not waits
        waiting += sent is None and waits
        return sent

    final_control._fast_tick = counting
    try:
        result = runner.run(scenario.load("corridor_100m"))
    finally:
        final_control._fast_tick = real
    stops = [line for _, line in result.link.events if line.startswith(("EVT:WATCHDOG", "EVT:FAULT"))]
    assert stops == ["EVT:WATCHDOG"]
    assert calls > 2000 and refused == 3 and waiting == C.NEUTRAL_TICKS, (calls, refused, waiting)


SCENARIOS = ["corridor_closed", "fault_encoder_reversed", "fault_motor_dead", "fault_wheel_locked",
             "fault_encoder_noise", "fault_reset", "watchdog", "reversal_pivot", "fault_silence"]


@pytest.mark.parametrize("name", SCENARIOS)
def test_a_scenario_runs_the_same_with_the_python_tick(name: str) -> None:
    """The same scenario with the C tick and with the Python tick only: every tick's
    state, the plant's motion and every byte the board sent."""
    sc = scenario.load(name)
    real = final_control._fast_tick
    try:
        a = runner.run(sc)
        final_control._fast_tick = None
        b = runner.run(sc)
    finally:
        final_control._fast_tick = real
    for record, key in (("truth", "pose"), ("board", "setpoint"), ("board", "measured"), ("board", "pwm"),
                        ("board", "counts"), ("truth", "wheel_speed"), ("board", "tick_cycles")):
        assert np.array_equal(getattr(getattr(a, record), key), getattr(getattr(b, record), key)), key
    assert a.link.lines == b.link.lines


def test_pure_python_when_asked() -> None:
    code = ("from wcdrive.firmware import tick_fast, final_control; "
            "print(tick_fast.fast, final_control._fast_tick)")
    env = {**os.environ, "WCDRIVE_PURE_TICK": "1"}
    run = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["None", "None"]


def test_bind_checks_the_state_type() -> None:
    @dataclasses.dataclass
    class NoSlots:
        x: int = 0

    assert tick_fast.fast is not None
    with pytest.raises(TypeError):
        tick_fast.fast._bind(NoSlots, tick_fast._constants(), {})
    with pytest.raises(ValueError):
        tick_fast.fast._bind(FirmwareState, {}, {})


def test_a_bind_that_fails_leaves_the_python_tick(monkeypatch, caplog) -> None:
    """What ``_bind`` refuses (here: no constants) is a warning and the Python tick, not
    an import error of the firmware modules."""
    monkeypatch.setattr(tick_fast, "_constants", lambda: {})
    assert tick_fast.load_fast() is None
    assert "pure Python" in caplog.text


# ---- the twin rule: a change to the tick touches control.py and tick_fast.c alike ----
#: Fields only the Python tick writes: those of the ticks the C tick declines (a fault
#: latches, whose emergency halt sets faultFlags and emergencyStop, keeps the integrals
#: and setpoints it began from (haltIntegral*, haltSetpoint*) and forgets lastTravel),
#: and a hold's start or rollaway, which set holdRollaway (the C tick takes only
#: a hold already on, its wheels within the deadband), and a halt at the chair's limit
#: (an overspeed, both wheels at their limit), which sets limitLatched; and the wait for
#: neutral and the inhibit inputs, whose fields only a tick that waits or reads an input
#: (declined) or the watchdog's stop of
#: motion (declined) writes. Any other field the Python tick writes, the C tick must
#: write too.
PYTHON_ONLY = {"emergencyStop", "faultFlags", "lastTravel", "holdRollaway", "limitLatched", "haltIntegralL",
               "haltIntegralR", "haltSetpointL", "haltSetpointR", "needNeutral", "neutralSeen",
               "neutralTicks", "notNeutralSent", "notNeutralPending", "notNeutralTicks", "neutralFault",
               "inhibitTick", "inhibitStable", "inhibitCountL", "inhibitCountR", "inhibitLatched",
               "inhibitPending", "inhibitOn", "inhibitCountP", "brakePhase", "brakeTicks",
               "brakeStatusTicks", "thermalRollback", "thermalPending", "batteryLow", "batteryPending"}
_FIRMWARE = Path(tick_fast.__file__).resolve().parent


def python_tick_writes(sources: dict[str, str]) -> set[str]:
    """The ``FirmwareState`` fields that ``control_tick`` and every function it calls
    (in ``sources``: module name -> text) assign."""
    funcs: dict[str, ast.FunctionDef] = {}
    for text in sources.values():
        funcs.update({n.name: n for n in ast.parse(text).body if isinstance(n, ast.FunctionDef)})
    seen: set[str] = set()
    todo = ["control_tick"]
    while todo:
        name = todo.pop()
        if name in seen or name not in funcs:
            continue
        seen.add(name)
        for node in ast.walk(funcs[name]):
            if isinstance(node, ast.Call):
                f = node.func
                if isinstance(f, (ast.Name, ast.Attribute)):
                    todo.append(f.id if isinstance(f, ast.Name) else f.attr)
    written: set[str] = set()
    for name in seen:
        states = {a.arg for a in funcs[name].args.args
                  if a.annotation is not None and "FirmwareState" in ast.unparse(a.annotation)}
        written |= {node.attr for node in ast.walk(funcs[name])
                    if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
                    and isinstance(node.value, ast.Name) and node.value.id in states}
    return written


def c_tick_writes(text: str) -> set[str]:
    """The fields tick_fast.c writes back: ``SETI``/``SETF``, and slots it marks written."""
    body = re.sub(r"#define[^\n]*", "", text)
    return (set(re.findall(r"\bSET[IF]\((\w+),", body))
            | set(re.findall(r"written\[F_(\w+)\]\s*=[^=]", body))
            | set(re.findall(r"\b[id]\[F_(\w+)\]\s*=[^=]", body)))


def _sources() -> tuple[dict[str, str], str]:
    modules = ("control", "motion", "output", "inhibit", "drive", "brake", "motors", "thermal", "battery")
    py = {m: (_FIRMWARE / f"{m}.py").read_text() for m in modules}
    return py, (_FIRMWARE / "csrc" / "tick_fast.c").read_text()


def test_the_c_tick_writes_every_field_the_python_tick_writes() -> None:
    py, c = _sources()
    python, native = python_tick_writes(py), c_tick_writes(c)
    assert len(python) > 40
    assert python - native == PYTHON_ONLY, "fields the Python tick writes and the C tick does not"
    assert native - python == set(), "fields the C tick writes and the Python tick does not"


def test_the_twin_check_sees_a_field_left_out() -> None:
    """The check can fail: a field the Python tick starts writing, or one the C tick
    stops writing."""
    py, c = _sources()
    py["control"] += "\n\ndef _extra(s: FirmwareState) -> None:\n    s.rxCount = 0\n"
    py["control"] = py["control"].replace("def control_tick(", "def control_tick_(", 1)
    py["control"] += "\n\ndef control_tick(s: FirmwareState) -> None:\n    control_tick_(s)\n    _extra(s)\n"
    assert "rxCount" in python_tick_writes(py) - c_tick_writes(c)
    dropped = c.replace("SETF(rawVelL,", "(void)(rawVelL,", 1)
    assert "rawVelL" not in c_tick_writes(dropped) and "rawVelL" in c_tick_writes(c)
