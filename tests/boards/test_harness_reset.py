"""Resets in the simavr harness (a reset, DTR): ``VirtualMega.reset``
(external, brown-out, power-on) and the AVR's own watchdog, with MCUSR as the chip
shows it, the clock running on, the stimulus kept; shown on tiny AVR programs compiled
here with avr-gcc (no Arduino core), then on the firmware and on the live board."""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import pytest

from wcdrive.boards.simavr.mega_board import MegaBoard
from wcdrive.boards.simavr.virtual_mega import (
    BORF,
    ENCODER_PINS,
    EXTRF,
    F_CPU,
    PORF,
    WDRF,
    HarnessError,
    VirtualMega,
)
from wcdrive.protocol.codec import encode_wheel, frame

pytestmark = pytest.mark.simavr

# A program that records MCUSR at boot, counts its boots in .noinit (SRAM the C runtime
# leaves alone, so the count survives every reset but a power-on), and either clears
# MCUSR and arms the watchdog at 60 ms (the default), or, with -DKEEP_MCUSR, leaves
# MCUSR as it found it and arms the watchdog on its first boot only; -DHALT stops the
# core on the first boot (sleep with interrupts off); -DSEND sends "B" and the boot
# count on the USART at 115200 baud, then echoes what it receives.
PROGRAM = r"""
#include <avr/io.h>
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <stdint.h>

volatile uint8_t boots __attribute__((section(".noinit")));
volatile uint8_t bootMcusr;
volatile uint8_t bootWdtcsr;
volatile uint8_t bootPine;
volatile uint32_t spins;

static void put(uint8_t c) {
  while (!(UCSR0A & _BV(UDRE0))) {}
  UDR0 = c;
}

int main(void) {
  bootMcusr = MCUSR;
  bootWdtcsr = WDTCSR;
  bootPine = PINE;
#ifndef KEEP_MCUSR
  MCUSR = 0;
  wdt_disable();
#endif
  boots++;
#ifdef HALT
  if (boots == 1) {
    cli();
    sleep_enable();
    sleep_cpu();
  }
#endif
#ifdef SEND
  UBRR0 = 16;                       /* 115200 baud, U2X */
  UCSR0A = _BV(U2X0);
  UCSR0B = _BV(RXEN0) | _BV(TXEN0);
  put('B');
  put('0' + boots);
  for (;;) {
    if (UCSR0A & _BV(RXC0)) put(UDR0);
  }
#endif
#ifdef KEEP_MCUSR
  if (boots == 1) wdt_enable(WDTO_60MS);
#else
  wdt_enable(WDTO_60MS);
#endif
  for (;;) spins++;
}
"""

#: simavr's watchdog oscillator is the nominal 128 kHz: WDTO_60MS is 8192 of its
#: cycles, 64 ms; after a watchdog reset with WDRF still set, 2048 cycles, 16 ms.
WDT_60MS = 8192 * F_CPU // 128_000
WDT_16MS = 2048 * F_CPU // 128_000


def compile_program(directory: Path, name: str, *defines: str) -> Path:
    if shutil.which("avr-gcc") is None:
        pytest.skip("avr-gcc is not installed")
    source = directory / "reset_probe.c"
    source.write_text(PROGRAM)
    elf = directory / f"{name}.elf"
    subprocess.run(["avr-gcc", "-mmcu=atmega2560", "-Os", "-DF_CPU=16000000UL",
                    *[f"-D{d}" for d in defines], "-o", str(elf), str(source)], check=True)
    return elf


@pytest.fixture(scope="module")
def programs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    directory = tmp_path_factory.mktemp("reset_probe")
    return {"wdt": compile_program(directory, "wdt"),
            "keep": compile_program(directory, "keep", "KEEP_MCUSR"),
            "halt": compile_program(directory, "halt", "HALT"),
            "send": compile_program(directory, "send", "SEND")}


def b(mega: VirtualMega, name: str) -> int:
    return int(mega.read(name, "B"))


def test_the_first_power_on_shows_porf(programs: dict[str, Path]) -> None:
    with VirtualMega(programs["wdt"]) as mega:
        assert mega.mcusr == PORF
        assert [(r.cycle, r.cause, r.mcusr) for r in mega.resets] == [(0, "power_on", PORF)]
        assert mega.boot_cycle == 0
        mega.run_for(0.001)
        assert (b(mega, "bootMcusr"), b(mega, "boots")) == (PORF, 1)
        assert mega.mcusr == 0                          # the program cleared it


def test_the_watchdog_resets_a_program_that_never_feeds_it(programs: dict[str, Path]) -> None:
    with VirtualMega(programs["wdt"]) as mega:
        mega.run_for(0.2)
        resets = mega.resets[1:]
        assert [r.cause for r in resets] == ["watchdog"] * 3
        assert all(r.mcusr == WDRF for r in resets)    # PORF was cleared by the program
        # 64 ms after wdt_enable, which runs some 80 cycles after each boot
        gaps = [b_.cycle - a.cycle for a, b_ in zip(mega.resets, resets, strict=False)]
        assert all(WDT_60MS < g < WDT_60MS + 200 for g in gaps), gaps
        assert (b(mega, "bootMcusr"), b(mega, "boots")) == (WDRF, 4)   # .noinit kept
        assert mega.boot_cycle == resets[-1].cycle
        assert mega.cycle >= round(0.2 * F_CPU)          # the clock ran on
        assert [h.function for h in mega.take_hits()] == ["main"] * 4


@pytest.mark.parametrize(("cause", "flag", "boots"), [("external", EXTRF, 2), ("brownout", BORF, 2),
                                                      ("power_on", PORF, 1)])
def test_a_reset_shows_its_cause(programs: dict[str, Path], cause: str, flag: int, boots: int) -> None:
    with VirtualMega(programs["wdt"]) as mega:
        mega.run_for(0.01)
        at = mega.cycle
        reset = mega.reset(cause)
        assert (reset.cycle, reset.cause, reset.mcusr) == (at, cause, flag)
        assert mega.cycle == at and mega.boot_cycle == at
        assert mega.read_bytes(0x60, 1)[0] == 0          # WDTCSR: the watchdog is off
        mega.run_for(0.001)
        assert (b(mega, "bootMcusr"), b(mega, "boots")) == (flag, boots)   # power-on clears SRAM
        mega.run_for(0.1)                                  # and the program's watchdog works again
        assert mega.resets[-1].cause == "watchdog"
        assert mega.resets[-1].cycle - at == pytest.approx(WDT_60MS, abs=200)


def test_unknown_causes_are_refused(programs: dict[str, Path]) -> None:
    with VirtualMega(programs["wdt"]) as mega:
        for cause in ("watchdog", "dtr", ""):
            with pytest.raises(ValueError, match="reset cause"):
                mega.reset(cause)


def test_flags_accumulate_and_wdrf_keeps_the_watchdog_running(programs: dict[str, Path]) -> None:
    """As on the chip: a reset adds its flag to those not cleared, and while WDRF is set
    the watchdog runs at its shortest period (16 ms) after any reset but a power-on."""
    with VirtualMega(programs["keep"]) as mega:
        mega.run_for(0.085)                               # 64 ms, then 16 ms
        causes = [(r.cause, r.mcusr) for r in mega.resets]
        assert causes == [("power_on", PORF), ("watchdog", PORF | WDRF), ("watchdog", PORF | WDRF)]
        assert mega.resets[2].cycle - mega.resets[1].cycle == pytest.approx(WDT_16MS, abs=10)
        reset = mega.reset("external")
        assert reset.mcusr == PORF | WDRF | EXTRF
        assert mega.read_bytes(0x60, 1)[0] & 0x08        # WDE forced on by WDRF
        mega.run_for(0.001)
        assert b(mega, "bootWdtcsr") == 0x08
        mega.run_for(0.02)
        assert mega.resets[-1].cause == "watchdog"
        assert mega.resets[-1].cycle - reset.cycle == pytest.approx(WDT_16MS, abs=10)
        reset = mega.reset("power_on")                    # clears every flag but PORF
        assert reset.mcusr == PORF and mega.read_bytes(0x60, 1)[0] == 0
        mega.run_for(0.001)
        assert b(mega, "boots") == 1


def test_a_reset_taken_when_the_watchdog_was_due(programs: dict[str, Path]) -> None:
    """A reset at the very instruction at which the watchdog expired: WDRF beside the
    cause's flag (a power-on: PORF alone, the watchdog off)."""
    with VirtualMega(programs["wdt"]) as mega:
        mega.run_for(0.1)
        due = mega.resets[1].cycle
    for cause, flags, wdtcsr in (("external", EXTRF | WDRF, 0x08), ("power_on", PORF, 0)):
        with VirtualMega(programs["wdt"]) as mega:
            mega.run_until(due)                  # the watchdog fired; its reset is not taken yet
            assert len(mega.resets) == 1
            reset = mega.reset(cause)
            assert (reset.cycle, reset.mcusr) == (due, flags)
            assert mega.read_bytes(0x60, 1)[0] == wdtcsr
            mega.run_for(0.001)
            assert [r.cause for r in mega.resets] == ["power_on", cause]


def test_pins_driven_from_outside_keep_their_levels(programs: dict[str, Path]) -> None:
    with VirtualMega(programs["wdt"]) as mega:
        a_pin, b_pin = ENCODER_PINS["left"]              # PE4, PE5, high from cycle 0
        mega.set_pin(b_pin, 0, at=mega.cycle + 100)
        mega.run_for(0.01)
        pine = mega.read_bytes(0x2C, 1)[0]
        assert pine & 0x30 == 0x10
        mega.reset()
        assert mega.read_bytes(0x2C, 1)[0] & 0x30 == 0x10     # at the reset vector already
        mega.set_pin(a_pin, 0, at=mega.cycle + 1000)          # stimulus after the reset
        mega.run_for(0.001)
        assert b(mega, "bootPine") & 0x30 == 0x10
        assert mega.read_bytes(0x2C, 1)[0] & 0x30 == 0x00
        mega.run_for(0.1)                                      # through a watchdog reset too
        assert mega.resets[-1].cause == "watchdog"
        assert mega.read_bytes(0x2C, 1)[0] & 0x30 == 0x00


def test_bytes_queued_across_a_reset_still_arrive(programs: dict[str, Path]) -> None:
    with VirtualMega(programs["send"]) as mega:
        mega.run_for(0.001)
        assert mega.take_tx_text() == "B1"
        cycles = mega.send(b"xyz", at=mega.cycle + round(0.002 * F_CPU))
        mega.reset()
        mega.run_for(0.005)
        tx = mega.take_tx()
        assert bytes(x for _, x in tx) == b"B2xyz"
        assert all(c > mega.boot_cycle for c, _ in tx)
        # each byte echoed after it arrived, on the clock that ran on
        assert all(echo > sent for (echo, _), sent in zip(tx[2:], cycles, strict=True))


def test_a_reset_revives_a_stopped_core(programs: dict[str, Path]) -> None:
    with VirtualMega(programs["halt"]) as mega:
        with pytest.raises(HarnessError, match="stopped"):
            mega.run_for(0.01)
        mega.reset()
        mega.run_for(0.01)
        assert b(mega, "boots") == 2 and mega.read("spins", "I") > 0


# ---- the firmware ----------------------------------------------------------------------
def framed(command: bytes, seq: int) -> bytes:
    return frame(command, seq)


#: The neutral command a host sends before motion ("Neutral before motion"): the board
#: drives once it has stood NEUTRAL_TICKS ticks (0.12 s is enough wherever it lands).
NEUTRAL = encode_wheel(0.0, 0.0)


def drive(mega: VirtualMega) -> None:
    """Boots, says hello, sends its neutral command and drives both wheels (the wheels
    held still: the PID winds up)."""
    mega.run_for(0.02)
    mega.send(framed(b"hello", 1))
    mega.run_for(0.06)
    mega.send(framed(NEUTRAL, 100))
    mega.run_for(0.12)
    for seq in range(2, 6):
        mega.send(framed(encode_wheel(6.0, 6.0), seq))
        mega.run_for(0.05)
    assert mega.pwm("left") > 0 and mega.pwm("right") > 0


def firmware_with_boot_cause(mega: VirtualMega) -> None:
    mega.run_for(0.01)
    text = mega.take_tx_text()
    if "BOOT:final_control," not in text:
        pytest.skip("this firmware does not report its reset cause yet")


@pytest.mark.parametrize(("cause", "word"), [("external", "EXTERNAL"), ("brownout", "BROWN_OUT"),
                                             ("power_on", "POWER_ON")])
def test_the_firmware_is_unpowered_from_the_first_instruction_after_a_reset(
        elf: Path, cause: str, word: str) -> None:
    with VirtualMega(elf) as mega:
        firmware_with_boot_cause(mega)
        drive(mega)
        mega.take_tx()
        reset = mega.reset(cause)
        assert (mega.pwm("left"), mega.pwm("right"), mega.relay()) == (0, 0, 0)
        # and every 500 cycles through boot, setup() and 300 ms of ticks
        end = mega.cycle + round(0.3 * F_CPU)
        while mega.cycle < end:
            mega.run_until(mega.cycle + 500)
            assert (mega.pwm("left"), mega.pwm("right")) == (0, 0)
        text = mega.take_tx_text()
        assert text.startswith(f"BOOT:final_control,{word}\r\n"), text[:80]
        assert reset.mcusr == {"external": EXTRF, "brownout": BORF, "power_on": PORF}[cause]
        assert mega.mcusr == 0                           # read and cleared at boot
        assert "ACK:" not in text                        # nothing executed again
        # the board speaks again: hello; the host's motion frame, as it was before the
        # reset, is refused (neutral before motion); a neutral frame, then it drives
        mega.send(framed(b"hello", 6))
        mega.run_for(0.1)
        assert "HELLO:3," in mega.take_tx_text()
        mega.send(framed(encode_wheel(6.0, 6.0), 7))
        mega.run_for(0.2)
        assert "NAK:7,neutral" in mega.take_tx_text() and mega.pwm("left") == 0
        mega.send(framed(NEUTRAL, 8))
        mega.run_for(0.12)
        mega.send(framed(encode_wheel(6.0, 6.0), 9))
        mega.run_for(0.2)
        assert "ACK:9" in mega.take_tx_text() and mega.pwm("left") > 0


@pytest.mark.thorough       # 17 s; at the fast depth tests/transports/test_dtr_reset.py resets live boards
def test_a_live_board_resets_on_a_dtr_pulse(elf: Path) -> None:
    board = MegaBoard(elf)
    sent: list[int] = []
    board.on_step = lambda tx: sent.extend(b for _, b in tx)      # the probe sees the TX too
    board.start()
    try:
        received = bytearray()

        def read_for(seconds: float) -> bytes:
            end = time.monotonic() + seconds
            out = bytearray()
            while time.monotonic() < end:
                out += board.read(4096, timeout=0.02)
            received.extend(out)
            return bytes(out)

        read_for(0.1)
        board.write(framed(b"hello", 1))
        board.write(framed(NEUTRAL, 100))
        # until a TLM line's state (its last field) says the neutral has stood
        deadline = time.monotonic() + 20
        while (not any(line.startswith(b"TLM:") and line.endswith(b",0")
                       for line in bytes(received).split(b"\r\n"))
               and time.monotonic() < deadline):
            read_for(0.05)
        for seq in range(2, 12):
            board.write(framed(encode_wheel(3.0, 3.0), seq))
            read_for(0.05)
        assert b"ACK:11" in received
        assert board.mega.pwm("left") > 0 or board.mega.pwm("right") > 0
        reset = board.reset()
        assert reset.cause == "external" and reset.mcusr == EXTRF
        assert board.between_steps(lambda mega: (mega.pwm("left"), mega.pwm("right"), mega.boot_cycle)) \
            == (0, 0, reset.cycle)
        assert b"BOOT:final_control,EXTERNAL\r\n" in read_for(0.3)
        assert bytes(sent).startswith(bytes(received[:len(sent)])) and b"BOOT:" in bytes(sent)
        assert board.pose() is not None
    finally:
        board.close()


def test_a_live_board_takes_a_positive_speed(elf: Path) -> None:
    with pytest.raises(ValueError, match="speed"):
        MegaBoard(elf, speed=0.0)
