"""No normal scenario trips a fault: every bundled scenario but the ``fault_*`` ones,
driven in closed loop on the port (bit-exact with the firmware, see
tests/firmware/test_differential.py), never latches a fault, and each detector stays clear of
its threshold. The margins found are printed (``pytest -s``).

The motor rule's margin is the effort counted by a wheel that strains alone: the ticks
of its run of effort without progress in which its partner counted none. Both wheels
counting at once (both at full duty short of top speed on a sagging battery, say) is a
load they share, which the rule does not blame (neither leads), so it does not eat the
margin, and neither does the tick or two by which one wheel's shared run outlasts the
other's (battery_low_flat: 9 ticks together, then 1 alone)."""

from __future__ import annotations

import pytest

from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.firmware import constants as C
from wcdrive.plant import Gyro, Plant
from wcdrive.sim.scenario import bundled, load

NORMAL = [p.stem for p in bundled() if not p.stem.startswith("fault_")]


@pytest.mark.parametrize("name", NORMAL)
def test_no_bundled_scenario_trips_a_fault(name: str) -> None:
    scenario = load(name)
    plant = Plant(scenario.params())
    loop = PortLoop(plant, Gyro(scenario.params(), 0))
    for t, data in scenario.host_commands():
        if t < scenario.duration:
            loop.send(data, at=round(t * F_CPU))
    peak = {"stall": 0, "reverse": 0, "runaway": 0, "effort": 0}
    alone = [0, 0]              # each wheel's ticks of its effort run with its partner at 0
    fewest_counts = 10**9
    previous: tuple[int, ...] | None = None

    def on_tick(_: float) -> None:
        nonlocal previous, fewest_counts
        s = loop.fw.state
        peak["stall"] = max(peak["stall"], s.stallTicksL, s.stallTicksR)
        peak["reverse"] = max(peak["reverse"], s.reverseTicksL, s.reverseTicksR)
        peak["runaway"] = max(peak["runaway"], s.runawayTicksL, s.runawayTicksR)
        for i, (own, partner) in enumerate(((s.effortTicksL, s.effortTicksR),
                                            (s.effortTicksR, s.effortTicksL))):
            alone[i] = 0 if own == 0 else alone[i] + (partner == 0)   # docstring
        peak["effort"] = max(peak["effort"], *alone)
        if previous is not None:
            for count, was, pwm, direction, setpoint in ((s.encTickL, *previous[0::2]),
                                                          (s.encTickR, *previous[1::2])):
                toward = setpoint != 0.0 and (direction == C.HIGH) == (setpoint > 0.0)
                if pwm >= C.FAULT_STALL_PWM and toward:
                    fewest_counts = min(fewest_counts, abs(count - was))
        previous = (s.encTickL, s.encTickR, s.pwmL, s.pwmR, s.dirL, s.dirR, s.setpointL, s.setpointR)

    loop.run_until(round(scenario.duration * F_CPU), on_tick)
    out = b"".join(data for _, data in loop.take_output())
    print(f"{name}: stall ticks {peak['stall']}/{C.FAULT_STALL_TICKS}, reverse ticks "
          f"{peak['reverse']}/{C.FAULT_REVERSE_TICKS}, runaway ticks {peak['runaway']}/"
          f"{C.FAULT_RUNAWAY_TICKS}, effort ticks {peak['effort']}/"
          f"{C.FAULT_EFFORT_TICKS}, fewest counts in a driven tick {fewest_counts}")
    assert b"EVT:FAULT" not in out and loop.fw.state.faultFlags == 0
    assert peak["stall"] == 0 and peak["reverse"] == 0 and peak["runaway"] == 0
    assert peak["effort"] <= C.FAULT_EFFORT_TICKS // 2
    assert fewest_counts >= 4
