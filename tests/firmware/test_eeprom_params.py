"""Parameters in EEPROM: ``save`` and ``defaults``, and the boot that loads
the saved parameters or keeps the defaults with an event, on the compiled firmware in
simavr and on the port, bit for bit (``hil.lockstep`` compares the EEPROM after every
event and carries the port's own EEPROM across each reset)."""

from __future__ import annotations

import struct

import pytest

from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware import constants as C
from wcdrive.firmware.eeprom import BLOCK_BYTES, DATA_BYTES, block_image, check, ee_crc, pack
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.state import FirmwareState
from wcdrive.hil.isr_cycles import isr_paths
from wcdrive.hil.lockstep import Recording, compare, record
from wcdrive.hil.traces import Trace
from wcdrive.protocol.codec import Event, frame, parse_line

pytestmark = pytest.mark.simavr

TUNED = [b"set:kp_l=3.5", b"set:ki_r=0.25", b"set:kd_l=0.0625", b"set:max_wheel=9.75",
         b"set:max_accel=6.5", b"set:estop_decel=40", b"set:watchdog_ms=250", b"set:profile=2",
         b"set:fwd_speed=1.5"]
TUNED_VALUES = {"kpL": 3.5, "kiR": 0.25, "kdL": 0.0625, "maxWheel": 9.75, "maxAccel": 6.5,
                "estopDecel": 40.0, "watchdogMs": 250, "profile": 2, "fwdSpeed": 1.5}


def _frames(commands: list[bytes], start: float = 0.02, spacing: float = 0.06) -> list[tuple[float, bytes]]:
    return [(start + spacing * k, frame(c, k + 1)) for k, c in enumerate(commands)]


def _same(trace: Trace) -> Recording:
    recording = record(trace)
    report = compare(recording)
    assert not report.mismatches, "\n".join([str(m) for m in report.mismatches[:10]] + [trace.describe()])
    return recording


def _boots(recording: Recording) -> list[bytes]:
    """The TX stream cut at its BOOT lines."""
    parts = recording.tx.split(b"BOOT:")
    return [b"BOOT:" + p for p in parts[1:]]


def _event(boot: bytes) -> str:
    second = boot.split(b"\r\n")[1]
    msg = parse_line(second)
    assert isinstance(msg, Event), second
    return msg.name


def test_saved_parameters_survive_a_reset() -> None:
    """hello, set every kind of parameter (a drive profile and a limit of its row among
    them), save, wait for the writes (176 bytes x 3.4 ms), reset (DTR): the new boot
    loads them, says so, and the port agrees bit for bit."""
    trace = Trace(1.6, _frames([b"hello", *TUNED, b"save"]), resets=[(1.3, "external")])
    recording = _same(trace)
    boots = _boots(recording)
    assert len(boots) == 2
    assert _event(boots[0]) == "PARAMS_DEFAULT,blank"
    assert _event(boots[1]) == "PARAMS_LOADED"
    booted = recording.resets[0][2]
    for name, value in TUNED_VALUES.items():
        assert booted[name] == value, name
    # One EEPROM-ready interrupt per byte after the first, and one that finds none left.
    assert len(recording.eeprom_writes) == BLOCK_BYTES
    gaps = {b - a for a, b in zip(recording.eeprom_writes, recording.eeprom_writes[1:], strict=False)}
    # simavr: 3.4 ms a byte and the EE-ready interrupt's own 105 cycles, give or take its
    # latency: the lowest priority, a ready waits for every handler above it that is
    # pending, at most once each (the encoders' INT2 to INT5, Timer0's compare and
    # overflow, the UART's receive and send, the ADC's: vectors 3 to 6, 21, 23, 25, 26
    # and 29, their longest paths read from the ELF). A byte whose ready falls on a Timer0 overflow
    # waits 180 to 210 cycles more than the others; 364 over was seen once the TX ring
    # grew and Timer0's phase moved (318 before, when the test allowed 105 + 220).
    waits = sum(max(cycles for cycles, _ in isr_paths(firmware_elf(), f"__vector_{n}"))
                for n in (3, 4, 5, 6, 21, 23, 25, 26, 29))
    assert all(0 <= g - 3400e-6 * F_CPU <= 105 + waits for g in gaps), (sorted(gaps), waits)
    image = recording.events[-1].eeprom
    assert image[:BLOCK_BYTES] == block_image(TUNED_VALUES)[:BLOCK_BYTES]
    assert image[BLOCK_BYTES:] == b"\xff" * (C.EEPROM_SIZE - BLOCK_BYTES)


def test_a_reset_in_the_middle_of_a_save_boots_to_the_defaults() -> None:
    """The block is half written when the board resets: bad CRC, the defaults."""
    commands = [b"hello", *TUNED, b"save"]
    trace = Trace(0.8, _frames(commands), resets=[(0.02 + 0.06 * len(commands) + 0.05, "external")])
    recording = _same(trace)
    assert 0 < len(recording.eeprom_writes) < BLOCK_BYTES - 1
    assert _event(_boots(recording)[1]) == "PARAMS_DEFAULT,crc"
    assert recording.resets[0][2]["kpL"] == C.KP_L


def _corrupt(kind: str) -> bytes:
    image = bytearray(block_image(TUNED_VALUES))
    if kind == "flipped byte":
        image[7] ^= 0x10
    elif kind == "flipped CRC":
        image[DATA_BYTES] ^= 0x01
    elif kind == "wrong version":
        image = bytearray(block_image(TUNED_VALUES, layout=C.EEPROM_LAYOUT + 1))
    elif kind in ("out of range", "NaN", "watchdog out of range"):
        field, raw = {"out of range": (1, struct.pack("<f", 11.0)),              # ki_l > 10
                      "NaN": (1 + 4 * 6, struct.pack("<I", 0x7FC00000)),         # max_wheel
                      "watchdog out of range": (DATA_BYTES - 2, struct.pack("<H", 99))}[kind]
        image[field:field + len(raw)] = raw
        image[DATA_BYTES:DATA_BYTES + 2] = struct.pack("<H", ee_crc(bytes(image[:DATA_BYTES])))
    elif kind == "blank":
        image = bytearray(b"\xff" * C.EEPROM_SIZE)
    elif kind == "zeros":
        image = bytearray(C.EEPROM_SIZE)
    return bytes(image)


@pytest.mark.parametrize(("kind", "why"), [
    ("blank", "blank"), ("zeros", "version"), ("flipped byte", "crc"), ("flipped CRC", "crc"),
    ("wrong version", "version"), ("out of range", "range"), ("NaN", "range"),
    ("watchdog out of range", "range"),
])
def test_a_corrupted_eeprom_boots_to_the_defaults_with_an_event(kind: str, why: str) -> None:
    """Power-on with a damaged block: the defaults and EVT:PARAMS_DEFAULT,<why>, on both
    sides; a save then repairs it and the next boot loads it."""
    image = _corrupt(kind)
    assert check(image[:BLOCK_BYTES]) == why
    trace = Trace(1.2, _frames([b"hello", b"set:kp_r=2.5", b"save"]), eeprom=image,
                  resets=[(0.9, "external")])
    recording = _same(trace)
    boots = _boots(recording)
    assert _event(boots[0]) == f"PARAMS_DEFAULT,{why}"
    for name in ("kpL", "kiL", "maxWheel", "watchdogMs"):
        assert recording.initial[name] == getattr(FirmwareState(), name)
    assert _event(boots[1]) == "PARAMS_LOADED"
    assert recording.resets[0][2]["kpR"] == 2.5


def test_a_good_image_loads_at_power_on() -> None:
    recording = _same(Trace(0.2, [], eeprom=block_image(TUNED_VALUES)))
    assert _event(_boots(recording)[0]) == "PARAMS_LOADED"
    for name, value in TUNED_VALUES.items():
        assert recording.initial[name] == value


def test_defaults_and_a_save_while_writing_and_a_save_that_changes_nothing() -> None:
    """``defaults`` puts the defaults back without writing; a second ``save`` while the
    first is being written is ``busy``; a save of what the EEPROM holds writes no byte."""
    commands = [b"hello", b"set:kp_l=4", b"save", b"save", b"defaults", b"get:kp_l"]
    trace = Trace(0.9, _frames(commands, spacing=0.03))
    recording = _same(trace)
    text = recording.tx.decode()
    assert "NAK:4,busy" in text and "ACK:3" in text and "ACK:5" in text
    assert "PAR:kp_l,7.2000" in text
    assert len(recording.eeprom_writes) == BLOCK_BYTES          # the whole block, once
    assert check(recording.events[-1].eeprom[:BLOCK_BYTES]) is None
    assert recording.events[-1].eeprom[:BLOCK_BYTES] == block_image({"kpL": 4.0})[:BLOCK_BYTES]
    again = Trace(0.3, _frames([b"hello", b"save"]), eeprom=block_image(TUNED_VALUES))
    rec2 = _same(again)
    assert "ACK:2" in rec2.tx.decode() and rec2.eeprom_writes == []
    assert recording.events[-1].after["kpL"] == C.KP_L          # defaults: in RAM only


def test_the_port_alone() -> None:
    """The port's save, its writes one interrupt at a time, and the boot it gives."""
    fw = Firmware()
    assert fw.boot_output().endswith(b"EVT:PARAMS_DEFAULT,blank\r\n")
    assert fw.state.txCredit == C.TX_CREDIT_BOOT - len(b"EVT:PARAMS_DEFAULT,blank\r\n")
    fw.feed(b"set:kp_l=3.5\nsave\n")
    assert fw.state.eeprom[0] == C.EEPROM_LAYOUT and fw.state.eeNext == 1 and fw.state.eeBusy
    for _ in range(BLOCK_BYTES):       # one interrupt per further byte, one to finish
        fw.eeprom_ready()
    assert not fw.state.eeBusy
    assert bytes(fw.state.eeprom[:BLOCK_BYTES]) == pack(fw.state)
    booted = Firmware(eeprom=fw.state.eeprom, cause="EXTERNAL")
    assert booted.boot_output() == b"BOOT:final_control,EXTERNAL\r\nEVT:PARAMS_LOADED\r\n"
    assert booted.state.kpL == 3.5
    with pytest.raises(ValueError):
        Firmware(eeprom=b"\xff" * 10)


def test_an_eeprom_write_never_blocks_loop_or_the_encoders(record_property) -> None:
    """Each EEPROM-ready interrupt (one byte written, or the end) takes a few hundred
    cycles, of which only its entry holds the other interrupts off (it turns them back
    on before its work: held for ~150 cycles, the encoders' interrupts merged edges at
    top speed, which the differential suite caught); the ``save`` line costs no more
    than a ``set:`` (tests/firmware/test_parse_budget.py). Measured in simavr (which writes a
    byte at once and raises the interrupt 3.4 ms later, as the chip's write time)."""
    mega = VirtualMega(hooks=("__vector_30",))
    try:
        for t, data in _frames([b"hello", *TUNED, b"save"]):
            mega.send(data, at=round(t * F_CPU))
        mega.break_on("__vector_30")
        isr, held = [], []
        while mega.run_to_break(round(1.4 * F_CPU)):
            start, sp = mega.cycle, mega.stack_pointer()
            mega.take_hits()
            while mega.stack_pointer() != sp + 3:          # reti pops the 3-byte PC
                mega.run_until(mega.cycle + 1)
                assert mega.cycle - start < 100_000
            isr.append(mega.cycle - start)
            # Interrupts are off from the vector to its sei, just before eepromReady's call.
            held.append(next(h.cycle for h in mega.take_hits() if h.function == "eepromReady") - start)
        assert len(isr) == BLOCK_BYTES
        assert max(held) < 60, held
        assert max(isr) < 400, isr
        record_property("eeprom_isr_cycles", max(isr))
        print(f"EEPROM-ready interrupt: {min(isr)} to {max(isr)} cycles, interrupts held off "
              f"{min(held)} to {max(held)}")
    finally:
        mega.close()


@pytest.mark.parametrize("seed", [1014, 1024])
def test_regression_the_eeprom_interrupt_held_the_encoders(seed: int) -> None:
    """Found by ``wcdrive verify``-style traces with saves at top edge rates: while the
    EEPROM-ready interrupt held the others off for its whole run, encoder edges merged
    into illegal transitions the decoder did not see (91 mismatches on seed 1014)."""
    from wcdrive.hil.traces import RandomDraw, generate_trace

    trace = generate_trace(RandomDraw(seed), 5.0)
    assert b"save" in b"".join(data for _, data in trace.serial)
    _same(trace)


@pytest.mark.parametrize("event", ["PARAMS_LOADED", "PARAMS_DEFAULT,blank", "PARAMS_DEFAULT,version",
                                   "PARAMS_DEFAULT,crc", "PARAMS_DEFAULT,range"])
def test_a_replay_boots_the_port_to_the_boards_event(event: str) -> None:
    """``bench replay`` sees the board's event, not its EEPROM: ``image_for`` gives one
    with which the port sends the same line."""
    from wcdrive.firmware.eeprom import image_for

    assert Firmware(eeprom=image_for(event)).boot_output().endswith(f"EVT:{event}\r\n".encode())


def test_the_virtual_megas_eeprom_survives_every_reset() -> None:
    """``VirtualMega``: erased at power-on, preloadable, kept across resets of every cause
    (non-volatile, as on the chip), its bounds checked."""
    image = block_image(TUNED_VALUES)
    with VirtualMega() as blank:
        assert blank.eeprom_size == C.EEPROM_SIZE
        assert blank.read_eeprom() == b"\xff" * C.EEPROM_SIZE
    with VirtualMega(eeprom=image) as mega:
        mega.run_for(0.01)
        for cause in ("external", "brownout", "power_on"):
            mega.reset(cause)
            mega.run_for(0.01)
            assert mega.read_eeprom() == image
        assert mega.take_tx_text().count("EVT:PARAMS_LOADED") == 4
        mega.write_eeprom(b"\x00", address=C.EEPROM_SIZE - 1)
        assert mega.read_eeprom(C.EEPROM_SIZE - 1, 1) == b"\x00"
        with pytest.raises(ValueError):
            mega.write_eeprom(b"\x00\x00", address=C.EEPROM_SIZE - 1)
        with pytest.raises(ValueError):
            mega.read_eeprom(C.EEPROM_SIZE, 1)
