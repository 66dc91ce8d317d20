"""``final_control.ino``'s ``setup()`` and ``loop()``: the port of the sketch as one
object with explicit inputs. One module per section of the sketch sits beside this one:
``commands`` (the serial parser), ``control`` (the control tick), ``motion`` (modes,
pivot, emergency halt), ``output`` (feedback, TLM and replies), ``quadrature`` (the
encoder ISRs), ``params``, ``constants`` and ``state`` (the globals).

``setup()`` returns a ``Firmware`` just out of the sketch's ``setup()``. The sketch's
``loop()`` does two things, and so does ``Firmware.loop``:

* ``feed(data)``: bytes read from the UART, each through ``processByte``;
* ``tick(now, count_l, count_r)``: ``controlTick(now)`` with the encoder counts it
  latched, when ``due(now)``.

Every call returns the bytes the firmware sends for it, and the whole state is
``state``. What the sketch reads from hardware (pin states, ``millis()``, the free
RAM) is an argument here.
"""

from __future__ import annotations

from wcdrive.firmware import constants as C
from wcdrive.firmware.commands import process_bytes, rx_gap
from wcdrive.firmware.constants import CONTROL_PERIOD_MS
from wcdrive.firmware.control import control_tick
from wcdrive.firmware.eeprom import eeprom_ready, load_params
from wcdrive.firmware.state import FirmwareState
from wcdrive.firmware.tick_fast import fast as _fast

_fast_tick = None if _fast is None else _fast.tick

#: ``BOOT:final_control,<cause>``: what setup() sends, the cause from MCUSR.
BOOT_LINE = b"BOOT:final_control,POWER_ON\r\n"


#: MCUSR's flags (avr/io.h): JTRF, WDRF, BORF, EXTRF, PORF.
JTRF, WDRF, BORF, EXTRF, PORF = 0x10, 0x08, 0x04, 0x02, 0x01


def reset_cause_name(mcusr: int) -> str:
    """``resetCauseName``: the BOOT line's cause word, the first of MCUSR's flags set
    (``captureResetCause`` read MCUSR before anything else ran)."""
    for flag, name in ((WDRF, "WATCHDOG"), (BORF, "BROWN_OUT"), (EXTRF, "EXTERNAL"),
                       (PORF, "POWER_ON"), (JTRF, "JTAG")):
        if mcusr & flag:
            return name
    return "NONE"


def boot_line(cause: str = "POWER_ON") -> bytes:
    """The BOOT line after a reset of the given cause (``reset_cause_name``)."""
    return b"BOOT:final_control," + cause.encode() + b"\r\n"
#: What ``measureFreeRam()`` reports on the Mega build (bytes between the heap and the
#: stack in loop()); the simulated board reports it too. tests/firmware/test_estop_and_reset.py checks
#: it against the ELF running in simavr, so a firmware change that moves it fails there.
FREE_RAM = 5512


class Firmware:
    """The sketch's globals (``state``) and its ``loop()``, one call per input."""

    def __init__(self, state: FirmwareState | None = None, *, boot_millis: int = 0,
                 eeprom: bytes | bytearray | None = None, cause: str = "POWER_ON") -> None:
        """A board just out of ``setup()`` (which sends the BOOT line of ``cause``, loads
        the parameters from ``eeprom``, the EEPROM's contents, erased when None, and ends
        with ``lastControlTime = millis()``), or one in any given ``state`` (then setup()
        does not run, and the boot output is the BOOT line alone)."""
        if state is None:
            state = FirmwareState(lastControlTime=boot_millis)
            if eeprom is not None:
                if len(eeprom) != len(state.eeprom):
                    raise ValueError(f"an EEPROM image is {len(state.eeprom)} bytes, not {len(eeprom)}")
                state.eeprom[:] = eeprom
            out = bytearray(boot_line(cause))
            load_params(state, out)
            self._boot = bytes(out)
        else:
            if eeprom is not None:
                raise ValueError("eeprom= is for a board that boots (no state given)")
            self._boot = boot_line(cause)
        self.state = state
        self.free_ram = FREE_RAM

    def boot_output(self) -> bytes:
        """What ``setup()`` sent: the BOOT line and the EEPROM's ``EVT:PARAMS_*`` line."""
        return self._boot

    def eeprom_ready(self) -> None:
        """``eepromReady``: the EEPROM-ready interrupt (a byte of a ``save`` is written)."""
        eeprom_ready(self.state)

    def loop(self, now: int, data: bytes, count_l: int, count_r: int, illegal_l: int = 0,
             illegal_r: int = 0) -> bytes:
        """One pass of ``loop()`` at ``millis() == now``: the received ``data``, then the
        control tick when it is due (with the latched counts)."""
        out = self.feed(data)
        if self.due(now):
            out += self.tick(now, count_l, count_r, illegal_l, illegal_r)
        return out

    def feed(self, data: bytes) -> bytes:
        """Received bytes, each through ``processByte``."""
        out = bytearray()
        process_bytes(self.state, data, out)
        return bytes(out)

    def rx_gap(self, lost: int = 1) -> None:
        """``rxGap(lost)``: loop() found ``lost`` losses counted before the next byte it
        reads (bytes dropped for a full ring, one per USART overrun; 255 at most)."""
        rx_gap(self.state, lost)

    def due(self, now: int) -> bool:
        """Whether a ``loop()`` pass at ``millis() == now`` runs the control tick."""
        return ((now - self.state.lastControlTime) & 0xFFFFFFFF) >= CONTROL_PERIOD_MS

    def due_after(self, now: int) -> int:
        """``due`` solved for the time: how many ms after ``millis() == now`` the control
        tick falls due, until an input changes the state (0: due now). ``due(now + m)``
        holds from ``m == due_after(now)`` on (``millis()`` wraps after 49 days)."""
        return max(0, CONTROL_PERIOD_MS - ((now - self.state.lastControlTime) & 0xFFFFFFFF))

    def tick(self, now: int, count_l: int, count_r: int, illegal_l: int = 0, illegal_r: int = 0,
             free_ram: int | None = None, storm_l: int = 0, storm_r: int = 0,
             rx_lost: int = 0, inputs: int = 0, supply: int = C.SUPPLY_NOMINAL_COUNTS,
             current_l: int = C.CURRENT_ZERO_COUNTS, current_r: int = C.CURRENT_ZERO_COUNTS) -> bytes:
        """``controlTick(now)``. What it latches from the interrupts (encoder counts,
        illegal transitions, storm flags, the RX interrupt's lost bytes) are inputs, and
        so is ``free_ram`` (what loop() measured before the tick; None: ``self.free_ram``,
        which starts at the figure of the Mega build, ``FREE_RAM``), and the input pins it
        reads (``inputs``: bit 0 inhibit input 1, bit 1 input 2, bit 2 the brake driver's
        status; 1 active, the pin LOW), the supply (``supply``: the ADC count at
        PIN_SUPPLY, 0 to 1023) and the motors' currents (``current_l``, ``current_r``: the
        ADC counts at PIN_CURRENT_L/R the interrupt converted after the last tick began;
        CURRENT_ZERO_COUNTS is 0 A)."""
        self.state.freeRam = self.free_ram if free_ram is None else free_ram
        if _fast_tick is not None:          # the common case in C (``tick_fast``), or None
            sent = _fast_tick(self.state, now, count_l, count_r, illegal_l, illegal_r, storm_l, storm_r,
                              rx_lost, inputs, supply, current_l, current_r)
            if sent is not None:
                return sent
        out = bytearray()
        control_tick(self.state, now, count_l, count_r, out, illegal_l, illegal_r, storm_l, storm_r,
                     rx_lost, inputs, supply, current_l, current_r)
        return bytes(out)


def setup(boot_millis: int = 0, eeprom: bytes | bytearray | None = None) -> Firmware:
    """The sketch's ``setup()``: a board that has just sent ``BOOT_LINE`` and its
    parameters' event (``eeprom``: the EEPROM's contents; erased when None), and whose
    ``lastControlTime`` is ``millis()`` at the end of ``setup()``."""
    return Firmware(boot_millis=boot_millis, eeprom=eeprom)
