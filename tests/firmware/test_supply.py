"""The supply the firmware measures and what a low battery does (docs/safety.md, "The
battery"): the ADC count at PIN_SUPPLY low-passed with a 1 s time constant, the
low-battery rollback of the top speed below BATTERY_LOW_V, and the UNDERVOLT fault below
BATTERY_CUTOFF_V. Each held here to figures worked by hand on the port;
tests/firmware/test_supply_lockstep.py runs them on both backends."""

from __future__ import annotations

import math

import pytest

from wcdrive.firmware import constants as C
from wcdrive.firmware.battery import FAULT_UNDERVOLT, battery_fault, battery_share, update_supply
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import ExtendedTelemetry, frame, parse_line


def counts(volts: float) -> int:
    """The count of ``volts`` at the battery, as the datasheet's ADC rounds it."""
    return round(volts / 6.0 / 5.0 * 1024)


def test_a_count_is_the_divided_battery_against_avcc() -> None:
    """5 V x 6 / 1024 a count: 24 V reads 819 counts and comes back within half a count."""
    assert C.SUPPLY_VOLTS_PER_COUNT == 5.0 * 6.0 / 1024
    assert counts(24.0) == C.SUPPLY_NOMINAL_COUNTS == 819
    s = FirmwareState(supplyTick=819)
    update_supply(s)
    assert s.supplyVolts == pytest.approx(24.0, abs=C.SUPPLY_VOLTS_PER_COUNT / 2)


def _settle(s: FirmwareState, volts: float, ticks: int) -> list[float]:
    seen = []
    for _ in range(ticks):
        s.supplyTick = counts(volts)
        update_supply(s)
        seen.append(s.supplyVolts)
    return seen


def test_the_filter_is_a_first_order_lag_of_one_second() -> None:
    """The first reading stands; a step from 24 to 22 V then closes by 5 % a tick: after
    n ticks 22 + 2 x 0.95^n V, so it crosses 23 V after ln 0.5 / ln 0.95 = 13.5 ticks:
    at the 14th (0.7 s), the rollback on with its event pending."""
    s = FirmwareState()
    _settle(s, 24.0, 1)
    start = s.supplyVolts
    seen = _settle(s, 22.0, 20)
    target = counts(22.0) * C.SUPPLY_VOLTS_PER_COUNT
    for n, v in enumerate(seen, 1):
        assert v == pytest.approx(target + (start - target) * 0.95**n, abs=1e-4)
    first_low = next(n for n, v in enumerate(seen, 1) if v < C.BATTERY_LOW_V)
    assert first_low == math.ceil(math.log((C.BATTERY_LOW_V - target) / (start - target)) / math.log(0.95))
    assert first_low == 14 and s.batteryLow == 1 and s.batteryPending == 1


def test_the_rollback_ends_half_a_volt_above_its_start() -> None:
    """Low at 22 V; back at 23.3 V it stays low (within BATTERY_HYSTERESIS), at 24 V it
    ends with EVT:BATTERY,0 pending."""
    s = FirmwareState()
    _settle(s, 22.0, 100)
    s.batteryPending = 0
    _settle(s, 23.3, 200)
    assert s.batteryLow == 1 and s.batteryPending == 0
    _settle(s, 24.0, 200)
    assert s.batteryLow == 0 and s.batteryPending == 2
    # the 23.5 V bracketed by the counts either side: 802 (23.496 V) stays low, 803
    # (23.525 V) ends it
    for volts, low in ((23.496, 1), (23.525, 0)):
        s = FirmwareState()
        _settle(s, 22.0, 100)
        _settle(s, volts, 300)
        assert s.batteryLow == low, volts


def test_the_rollback_lowers_the_top_speed_linearly_to_the_cutoff() -> None:
    """1 down to 23 V; at 21 V, 2 of the 3.5 V to the cut-off gone: 1 - 0.5 x 2 / 3.5 =
    71.4 %; 50 % at 19.5 V and below, where the fault latches."""
    for volts, share in ((25.0, 1.0), (23.0, 1.0), (22.0, 1 - 0.5 / 3.5), (21.0, 1 - 1.0 / 3.5),
                         (19.5, 0.5), (15.0, 0.5)):
        assert battery_share(FirmwareState(supplyVolts=volts)) == pytest.approx(share, abs=1e-6), volts
        assert battery_fault(FirmwareState(supplyVolts=volts)) == (FAULT_UNDERVOLT if volts < 19.5 else 0)


def test_a_cut_sense_wire_latches_the_fault_within_five_ticks() -> None:
    """A0 at 0 V from a 24 V reading: 24 x 0.95^n < 19.5 first at n = 5, the tick that
    latches UNDERVOLT; the chair driving stops along the emergency ramp."""
    fw = Firmware()
    fw.feed(b"hello:4\n")
    fw.state.needNeutral = 0
    fw.feed(frame(b"x:0.500,t:0.000", 1))
    out = b"".join(fw.tick(50 * k, 0, 0, supply=819) for k in range(1, 4))
    assert b"EVT:FAULT" not in out and fw.state.supplyVolts > 23.9 and fw.state.setpointR > 0.0
    lines = [fw.tick(50 * k, 0, 0, supply=0) for k in range(4, 9)]
    assert [b"EVT:FAULT,UNDERVOLT" in line for line in lines] == [False] * 4 + [True]
    assert fw.state.faultFlags == FAULT_UNDERVOLT and fw.state.emergencyStop == 1


def test_tlm_reports_the_filtered_supply_and_the_rollback() -> None:
    """TLM's 18th field is the filtered supply in tenths of a volt; state bit 7 the
    rollback."""
    fw = Firmware()
    fw.feed(b"hello:4\n")
    for k in range(1, 60):
        out = fw.tick(50 * k, 0, 0, supply=counts(22.4))
    tlm = next(m for m in map(parse_line, out.splitlines()) if isinstance(m, ExtendedTelemetry))
    assert tlm.supply_v == pytest.approx(22.4, abs=0.05) and tlm.battery_low
    assert b"EVT:BATTERY,1" not in out                # sent once, long before
