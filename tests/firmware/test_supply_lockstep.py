"""The supply and the low battery on both backends (docs/safety.md, "The battery"): the
compiled firmware in simavr reads the battery on A0 (``Trace.supply``: the mV put on the
pin, through the 6:1 divider), replayed on the port in lock step with no mismatch.
tests/firmware/test_supply.py holds the same rules to figures worked by hand."""

from __future__ import annotations

import pytest

from tests.support.recordings import board_lines, every, recorded, tick_states, turning
from wcdrive.boards.supply_sense import adc_counts, pin_millivolts
from wcdrive.firmware import constants as C
from wcdrive.firmware.battery import FAULT_UNDERVOLT
from wcdrive.hil.lockstep import Recording
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line

pytestmark = pytest.mark.simavr


def _drive(command: bytes, duration: float, supply: list[tuple[float, float]], speed: float = 3.0,
           first: tuple[bytes, ...] = ()) -> Recording:
    """``hello:4``, the commands ``first``, a neutral command, then ``command`` every
    0.1 s, framed, while the wheels turn at ``speed`` rad/s; the battery at each (s, V)
    of ``supply`` from then on."""
    writes = [*((0.02 + 0.01 * k, cmd) for k, cmd in enumerate((*first, b"x:0.000,t:0.000"))),
              *every(command, 0.2, duration - 0.1)]
    serial = [(0.01, b"hello:4\n")] + [(t, frame(cmd, k + 1)) for k, (t, cmd) in enumerate(writes)]
    return recorded(Trace(duration=duration, serial=serial,
                          supply=[(t, pin_millivolts(v)) for t, v in supply],
                          encoders={side: turning(duration, side == "left", speed)
                                    for side in ("left", "right")}))


def _tlm(rec: Recording) -> list[ExtendedTelemetry]:
    out = [parse_line(line) for line in board_lines(rec, b"TLM:")]
    assert all(isinstance(m, ExtendedTelemetry) for m in out)
    return out  # type: ignore[return-value]


def test_a_full_battery_reads_its_voltage_and_limits_nothing() -> None:
    """At 25.6 V (a full AGM pair at rest) the board reads 873 counts, reports 25.6 V in
    TLM, sends no battery event and drives its setpoints to what was asked."""
    rec = _drive(b"rp05.00,lp05.00", 2.0, [(0.0, 25.6)])
    ticks = tick_states(rec)
    assert all(a["supplyTick"] == adc_counts(pin_millivolts(25.6)) == 873 for _, a in ticks)
    assert {m.supply_v for m in _tlm(rec)} == {25.6} and not any(m.battery_low for m in _tlm(rec))
    assert board_lines(rec, b"EVT:BATTERY") == [] and ticks[-1][1]["setpointR"] == pytest.approx(5.0)


def test_a_low_battery_rolls_back_the_top_speed_and_recovers() -> None:
    """``max_wheel`` 4 rad/s and 4 asked, the wheels turning at 3.9; the battery at
    22.0 V from 3.5 s: the filtered supply crosses 23 V 0.6 to 0.7 s later
    (``EVT:BATTERY,1``, TLM state bit 7) and the setpoints fall to the share of max_wheel
    it allows (86 % at 22 V); back at 25 V from 6.0 s, the rollback ends above 23.5 V
    (``EVT:BATTERY,0``) and the setpoints climb back."""
    rec = _drive(b"rp04.00,lp04.00", 8.0, [(3.5, 22.0), (6.0, 25.0)], speed=3.9,
                 first=(b"set:max_wheel=4.0",))
    ticks = tick_states(rec)
    assert board_lines(rec, b"EVT:BATTERY") == [b"EVT:BATTERY,1", b"EVT:BATTERY,0"]
    low = [t for t, a in ticks if a["batteryLow"]]
    assert 4.05 <= low[0] <= 4.25 and 6.5 < low[-1] < 6.75
    before = next(a for t, a in ticks if t >= 3.45)
    assert before["setpointR"] == pytest.approx(4.0, abs=1e-6) and before["maxWheel"] == 4.0
    settled = next(a for t, a in ticks if t >= 5.95)
    share = 1 - 0.5 * (C.BATTERY_LOW_V - settled["supplyVolts"]) / 3.5
    assert settled["setpointL"] == settled["setpointR"] == pytest.approx(4.0 * share, rel=1e-4)
    assert 0.85 < share < 0.9           # headed for 86 %: 22 V, 2.5 time constants on
    assert ticks[-1][1]["setpointR"] == pytest.approx(4.0, abs=1e-6)
    seen = [m.battery_low for m in _tlm(rec)]
    assert any(seen) and not seen[-1]


def test_the_cutoff_latches_its_fault_and_stops_the_chair() -> None:
    """The battery at 18.5 V from 1.0 s while driving: the filtered supply passes below
    19.5 V 1.65 s later (ln 0.186 / ln 0.95 = 33 ticks): ``EVT:BATTERY,1`` first, then
    ``EVT:FAULT,UNDERVOLT``, the e-stop ramp and motion refused (``NAK:<seq>,fault``);
    TLM shows the fault and the supply."""
    rec = _drive(b"rp03.00,lp03.00", 3.5, [(1.0, 18.5)])
    ticks = tick_states(rec)
    assert board_lines(rec, b"EVT:FAULT,") == [b"EVT:FAULT,UNDERVOLT"]
    latched = next(t for t, a in ticks if a["faultFlags"])
    assert 2.55 <= latched <= 2.8
    at = next(a for t, a in ticks if t == latched)
    assert at["faultFlags"] == FAULT_UNDERVOLT and at["emergencyStop"] and at["targetR"] == 0.0
    assert at["supplyVolts"] < C.BATTERY_CUTOFF_V
    assert board_lines(rec, b"NAK:") and all(line.endswith(b",fault") for line in board_lines(rec, b"NAK:"))
    last = _tlm(rec)[-1]
    assert last.fault_names == ("UNDERVOLT",) and last.supply_v is not None and last.supply_v < 19.5


def test_a_board_whose_sense_reads_nothing_faults_at_its_first_tick() -> None:
    """A0 at 0 V from power-on (the divider unwired, the wire cut): the first tick's
    reading stands, 0 V, and ``UNDERVOLT`` latches there: the board never drives (its
    setpoints stay at zero; the wheels, turned by the trace, are held)."""
    rec = _drive(b"rp03.00,lp03.00", 1.0, [(0.0, 0.0)])
    ticks = tick_states(rec)
    assert ticks[0][1]["faultFlags"] == FAULT_UNDERVOLT
    assert all(a["setpointL"] == a["setpointR"] == 0.0 and a["faultFlags"] for _, a in ticks)
