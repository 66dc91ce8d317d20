"""The supply sense on the simulated boards (``wcdrive.boards.supply_sense``): the
battery through the 6:1 divider to A0, converted as simavr 1.6 converts it (AVcc 5 V,
x 1023); the harness's analog event reaching the chip's ADC (a tiny AVR program
compiled here, then the firmware); the plant's battery on A0 (``PlantOnPins``) and in
the port's tick (``PortLoop``), one count for one battery; the lock-step harness's
check of the count the tick latched; the random traces' supply changes.

Hand-worked figures: 24 V / 6 = 4000 mV, 4000 x 1023 // 5000 = 818 (the datasheet's
x 1024 gives 819, ``SUPPLY_NOMINAL_COUNTS``); 30 V = 5000 mV = 1023, full scale; the
plant's empty battery at rest, 23.6 V, is 3933 mV (3933.3), 3933 x 1023 // 5000 = 804
(804.7); 21 V = 3500 mV = 716 (716.1); 2500 mV = 511 (511.5).
"""

from __future__ import annotations

import dataclasses
import itertools
import shutil
import subprocess
from pathlib import Path

import pytest

from wcdrive.boards.port_loop import PortLoop
from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.boards.supply_sense import (
    AVCC_MV,
    NOMINAL_MV,
    SUPPLY_CHANNEL,
    SupplyOverrides,
    adc_counts,
    pin_millivolts,
)
from wcdrive.firmware import constants as C
from wcdrive.plant import ChairParams, Plant

#: The plant's battery, empty: 23.6 V open-circuit at rest (ChairParams).
EMPTY = ChairParams(battery_capacity_ah=50.0, battery_charge=0.0)


# ---- the conversions -------------------------------------------------------------------
def test_a_24_v_battery_is_4000_mv_at_a0_and_818_counts() -> None:
    assert SUPPLY_CHANNEL == C.PIN_SUPPLY == 0
    assert AVCC_MV == 5000
    assert pin_millivolts(24.0) == NOMINAL_MV == 4000
    assert adc_counts(4000) == 818
    assert C.SUPPLY_NOMINAL_COUNTS == 819          # the datasheet's x 1024: 0.1 % more


@pytest.mark.parametrize(("volts", "mv", "counts"), [
    (30.0, 5000, 1023), (23.6, 3933, 804), (21.0, 3500, 716), (15.0, 2500, 511),
    (0.0, 0, 0), (0.0035, 1, 0), (0.006, 1, 0)])
def test_battery_volts_to_millivolts_to_counts(volts: float, mv: int, counts: int) -> None:
    assert pin_millivolts(volts) == mv
    assert adc_counts(mv) == counts


def test_the_adc_clips_at_full_scale_and_the_pin_never_goes_negative() -> None:
    assert adc_counts(5001) == adc_counts(6000) == adc_counts(65535) == 1023
    assert adc_counts(4999) == 1022
    assert pin_millivolts(36.0) == 6000
    assert pin_millivolts(-5.0) == 0


def test_supply_overrides_hold_from_their_cycle_until_the_next() -> None:
    overrides = SupplyOverrides()
    overrides.set(200, 21.0)
    overrides.set(100, 25.0)
    overrides.set(300, None)
    assert [overrides.at(c) for c in (0, 99, 100, 199, 200, 299, 300, 10**9)] == [
        None, None, 25.0, 25.0, 21.0, 21.0, None, None]


# ---- the port --------------------------------------------------------------------------
def test_the_port_reads_an_ideal_supply_as_simavr_does() -> None:
    loop = PortLoop(Plant())
    loop.run_until(round(0.1 * F_CPU))
    assert loop.last_tick_cycle is not None
    assert loop.fw.state.supplyTick == 818             # not Firmware.tick's default, 819


def test_the_port_reads_the_plants_battery_and_a_callers_supply() -> None:
    plant = Plant(EMPTY)
    loop = PortLoop(plant)
    loop.run_until(round(0.1 * F_CPU))
    assert plant.battery[0] == pytest.approx(23.6)
    assert loop.fw.state.supplyTick == 804
    loop.set_supply(21.0, at=round(0.15 * F_CPU))
    loop.run_until(round(0.14 * F_CPU))
    assert loop.fw.state.supplyTick == 804
    loop.run_until(round(0.2 * F_CPU))
    assert loop.fw.state.supplyTick == 716
    loop.set_supply(None)                              # back to the plant's, now
    loop.run_until(round(0.3 * F_CPU))
    assert loop.fw.state.supplyTick == 804


# ---- the harness: a tiny AVR program that converts ADC0 over and over ------------------
# bootAdc: the ADC's data register read at boot, before any conversion; adcValue: the
# last conversion's result (ADCL then ADCH), read as each completes; reads: how many.
PROBE = r"""
#include <avr/io.h>
#include <stdint.h>

volatile uint16_t bootAdc;
volatile uint16_t adcValue;
volatile uint32_t reads;

int main(void) {
  bootAdc = ADC;
  ADMUX = _BV(REFS0);                                     /* ADC0 against AVcc */
  ADCSRA = _BV(ADEN) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
  ADCSRA |= _BV(ADSC);
  for (;;) {
    if (!(ADCSRA & _BV(ADSC))) {
      adcValue = ADC;
      reads++;
      ADCSRA |= _BV(ADSC);
    }
  }
}
"""


@pytest.fixture(scope="module")
def probe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("avr-gcc") is None:
        pytest.skip("avr-gcc is not installed")
    directory = tmp_path_factory.mktemp("adc_probe")
    source = directory / "adc_probe.c"
    source.write_text(PROBE)
    elf = directory / "adc_probe.elf"
    subprocess.run(["avr-gcc", "-mmcu=atmega2560", "-Os", "-DF_CPU=16000000UL", "-o", str(elf),
                    str(source)], check=True)
    return elf


def _adc(mega: VirtualMega) -> int:
    return int(mega.read("adcValue", "H"))


@pytest.mark.simavr
def test_the_board_starts_at_a_24_v_battery_against_a_5_v_avcc(probe: Path) -> None:
    with VirtualMega(probe) as mega:
        mega.run_for(0.005)
        assert mega.analog(SUPPLY_CHANNEL) == NOMINAL_MV
        assert mega.read("reads", "I") > 10
        assert _adc(mega) == 818                # simavr's own 3.3 V default would clip: 1023
        assert mega.read("bootAdc", "H") == 0   # the data register at reset, as on the chip


@pytest.mark.simavr
def test_an_analog_input_is_converted_from_its_cycle_on(probe: Path) -> None:
    with VirtualMega(probe) as mega:
        at = round(0.01 * F_CPU)
        mega.set_analog(SUPPLY_CHANNEL, 2500, at=at)
        assert mega.analog(SUPPLY_CHANNEL) == 2500      # what was last set, due or not
        mega.run_until(at - 500)
        assert _adc(mega) == 818
        mega.run_until(at + round(0.001 * F_CPU))
        assert _adc(mega) == 511
        for mv, counts in ((6000, 1023), (5000, 1023), (0, 0), (3933, 804)):
            mega.set_analog(SUPPLY_CHANNEL, mv)
            mega.run_for(0.001)
            assert _adc(mega) == counts


@pytest.mark.simavr
def test_analog_inputs_keep_their_millivolts_across_resets(probe: Path) -> None:
    with VirtualMega(probe) as mega:
        mega.set_analog(SUPPLY_CHANNEL, 3500)
        mega.run_for(0.002)
        assert _adc(mega) == 716
        for cause in ("external", "power_on"):
            mega.reset(cause)
            mega.run_for(0.002)
            assert mega.read("bootAdc", "H") == 0       # no conversion yet: the reset value
            assert _adc(mega) == 716


@pytest.mark.simavr
def test_analog_events_are_refused_outside_the_adc(probe: Path) -> None:
    with VirtualMega(probe) as mega:
        with pytest.raises(ValueError, match="analog input"):
            mega.set_analog(8, 1000)
        with pytest.raises(ValueError, match="65535"):
            mega.set_analog(0, 70000)
        with pytest.raises(ValueError, match="65535"):
            mega.set_analog(0, -1)


@pytest.mark.simavr
def test_the_plants_battery_goes_on_a0_at_the_steps_start(probe: Path) -> None:
    with VirtualMega(probe) as mega:
        pins = PlantOnPins(mega, Plant(EMPTY))
        for k in range(5):
            pins.step(k * 0.001, (k + 1) * 0.001)
        assert mega.analog(SUPPLY_CHANNEL) == 3933
        assert pins.supply_changes == [(0.0, 3933)]       # once: the battery rests
        assert _adc(mega) == 804                          # the port's count for it too
        mega.keep_records = False                         # a live board keeps no log
        pins.plant.s.soc = 1.0                            # charged: 25.6 V
        pins.step(0.005, 0.006)
        assert mega.analog(SUPPLY_CHANNEL) == pin_millivolts(25.6) == 4267
        assert pins.supply_changes == [(0.0, 3933)]


# ---- the firmware ----------------------------------------------------------------------
@pytest.mark.simavr
def test_the_firmware_latches_the_supply_count_each_tick(elf: Path) -> None:
    with VirtualMega(elf) as mega:
        mega.run_for(0.1)
        assert mega.read("supplyTick") == 818
        mega.set_analog(SUPPLY_CHANNEL, 3500)
        mega.run_for(0.05)
        assert mega.read("supplyTick") == 716


@pytest.mark.simavr
def test_the_lockstep_comparison_holds_the_latched_count_to_the_trace() -> None:
    from tests.support.recordings import recorded
    from wcdrive.hil.lockstep import compare
    from wcdrive.hil.traces import Trace

    trace = Trace(duration=1.2, serial=[(0.01, b"rp0,lp0,\n")],
                  supply=[(0.3, 3700), (0.6, 3500), (0.9, 0)])
    recording = recorded(trace)                       # 0 mismatches
    latched = {int(ev.after["supplyTick"]) for ev in recording.events if ev.kind == "tick"}
    assert latched == {818, adc_counts(3700), 716, 0}
    recording.trace = dataclasses.replace(trace, supply=[(0.3, 3700), (0.6, 3600), (0.9, 0)])
    fields = {m.field for m in compare(recording).mismatches}
    assert "supplyTick" in fields


# ---- the random traces ----------------------------------------------------------------
def test_random_traces_change_the_supply_and_nothing_else() -> None:
    from wcdrive.hil.traces import SUPPLY_SPACING_S, RandomDraw, generate_trace

    class Before(RandomDraw):
        supplies = False

    with_supply = 0
    for seed in range(60):
        trace = generate_trace(RandomDraw(seed), 5.0)
        before = generate_trace(Before(seed), 5.0)
        assert dataclasses.replace(trace, supply=[]).describe() == before.describe()
        assert before.supply == []
        if trace.supply:
            with_supply += 1
            assert trace.profile is None
            times = [t for t, _ in trace.supply]
            assert times == sorted(times) and 0.05 <= times[0] and times[-1] <= 4.95
            assert all(b - a >= SUPPLY_SPACING_S for a, b in itertools.pairwise(times))
            assert all(0 <= mv <= pin_millivolts(29.0) for _, mv in trace.supply)
    assert 5 <= with_supply <= 30
