"""The AVR's hardware watchdog, on the firmware in simavr: a ``loop()`` that hangs is
reset within the watchdog's period, the motors are unpowered from the first
instruction after the reset, and the board says why it rebooted.

The hang is made the way a firmware bug would make it: ``controlTick`` is sent back
into avr-libc's ``_exit`` (``cli`` and a jump to itself) by rewriting its return
address on the stack, so ``loop()`` never runs again.
"""

from __future__ import annotations

import numpy as np
import pytest
from elftools.elf.elffile import ELFFile

from tests.support.boards import ChairOnPins
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware import constants as C
from wcdrive.plant.encoders import EdgeTrain

pytestmark = pytest.mark.simavr

#: avr/wdt.h: WDTO_120MS is 3; the watchdog's oscillator runs at 128 kHz, so the
#: period is 16384 of its cycles (128 ms nominal).
WDT_PERIOD_S = (2048 << C.HW_WATCHDOG) / 128_000


def _symbol(elf: str, name: str) -> int:
    with open(elf, "rb") as handle:
        for section in ELFFile(handle).iter_sections():
            if section.name == ".symtab":
                for sym in section.iter_symbols():
                    if sym.name == name:
                        return int(sym["st_value"])
    raise KeyError(name)


def _hang_in_control_tick(mega: VirtualMega) -> int:
    """Stops at the next ``controlTick`` entry and makes it return into ``_exit``;
    returns the cycle of the hang."""
    mega.break_on("controlTick")
    assert mega.run_to_break(mega.cycle + F_CPU)
    mega.break_on()
    word = _symbol(str(mega.elf), "_exit") // 2
    sp = mega.stack_pointer()
    # ATmega2560: a 3-byte return address, high byte first, just above SP.
    address = sp + 1
    mega.write_bytes(address, bytes([(word >> 16) & 0xFF, (word >> 8) & 0xFF, word & 0xFF]))
    return mega.cycle


def test_a_hung_loop_is_reset_by_the_watchdog_and_the_motors_are_unpowered(elf) -> None:
    mega = VirtualMega(elf)
    rig = ChairOnPins(mega)
    rig.run_for(0.06)                                     # booted
    rig.neutral(b"x:0.000,t:0.000,\n")                  # the host's neutral first
    for _ in range(10):                                   # driving at 0.5 m/s
        rig.send_and_run(b"x:0.500,t:0.000,", 0.1)
    assert mega.pwm("left") > 0 and mega.pwm("right") > 0
    hung_at = _hang_in_control_tick(mega)
    # Until the watchdog bites, the outputs stay as they were: the hang's whole cost.
    while len(mega.resets) < 2 and mega.cycle - hung_at < 0.5 * F_CPU:
        mega.run_for(0.001)
    reset = mega.resets[-1]
    assert reset.cause == "watchdog" and reset.mcusr & 0x08     # WDRF
    after_s = (reset.cycle - hung_at) / F_CPU
    assert WDT_PERIOD_S * 0.9 <= after_s <= WDT_PERIOD_S * 1.1, after_s
    # From the first instruction after the reset the PWM pins are inputs: no drive.
    assert (mega.pwm("left"), mega.pwm("right")) == (0, 0)
    mega.run_for(0.1)
    text = bytes(b for c, b in mega.tx_log if c >= reset.cycle)
    assert text.startswith(b"BOOT:final_control,WATCHDOG\r\n"), text[:60]
    assert mega.read("resetCause") & 0x08
    assert mega.read("needNeutral") == 1                 # rebooted: motion waits for neutral
    mega.close()


def test_an_edge_storm_never_needs_the_watchdog(elf) -> None:
    """500,000 edges/s on both encoders: the storm guard masks both within a
    millisecond, the ticks keep their grid and the watchdog never fires (the bundled
    fault_encoder_noise_500k_both scenario holds the same for 3 s in closed loop)."""
    mega = VirtualMega(elf)
    mega.run_for(0.1)
    times = 0.2 + np.arange(0.0, 0.3, 1 / 500_000)
    chatter = np.where(np.arange(times.size) % 2 == 0, 0b01, 0b11)     # channel A toggling
    for side in ("left", "right"):
        mega.encoder_edges(side, EdgeTrain(times, chatter, 0, 0))
    mega.run_for(0.6)
    assert [r.cause for r in mega.resets] == ["power_on"]
    assert mega.read("stormL") != 0 and mega.read("stormR") != 0
    assert mega.read("faultFlags") == 0x30
    ticks = [h.cycle for h in mega.hit_log if h.function == "controlTick"]
    assert ticks and max(np.diff(ticks)) / F_CPU <= 0.0515
    mega.close()
