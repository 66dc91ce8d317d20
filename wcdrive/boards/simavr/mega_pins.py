"""The pins of a Mega running final_control: which port bit each pin the spec assigns
is (``ENCODER_PINS``, ``DIR_PINS``, ``RELAY_PIN``, ``BRAKE_PIN``, from the Arduino
pin numbers of protocol/spec.toml through ``MEGA_PORT_BIT``), and ``MegaPins``, what
the firmware drives on its outputs: a pin's level, the motors' PWM duty and
direction, the relay, the parking brake.

An output is read from the I/O registers the firmware writes (PORTx, DDRx, Timer2's
TCCR2A and OCR2A/B), not from a model of the pin: what the chip would put on the wire
is what the program set in those registers, and reading them costs no simulated
time.
"""

from __future__ import annotations

from wcdrive.boards.simavr.mega_memory import MegaMemory
from wcdrive.protocol.spec import integer

#: The Mega 2560's Arduino pin numbers (variants/mega/pins_arduino.h) as (port letter,
#: bit), for the pins the spec assigns.
MEGA_PORT_BIT = {2: ("E", 4), 3: ("E", 5), 7: ("H", 4), 8: ("H", 5), 9: ("H", 6), 10: ("B", 4),
                 11: ("B", 5), 18: ("D", 3), 19: ("D", 2), 22: ("A", 0), 23: ("A", 1), 24: ("A", 2),
                 25: ("A", 3), 26: ("A", 4)}


def _pin(name: str) -> tuple[str, int]:
    return MEGA_PORT_BIT[integer(name)]


# Pins of final_control (protocol/spec.toml, [pins]) as (port letter, bit).
ENCODER_PINS = {"left": (_pin("PIN_ENC_L_A"), _pin("PIN_ENC_L_B")),
                "right": (_pin("PIN_ENC_R_A"), _pin("PIN_ENC_R_B"))}
DIR_PINS = {"left": _pin("PIN_DIR_L"), "right": _pin("PIN_DIR_R")}
RELAY_PIN = _pin("PIN_RELAY")
BRAKE_PIN = _pin("PIN_BRAKE")
#: The inhibit inputs by number (1, 2): active LOW, pulled up (HIGH) when nothing drives them.
INHIBIT_PINS = {1: _pin("PIN_INHIBIT_1"), 2: _pin("PIN_INHIBIT_2")}
#: The brake driver's status output: pulled up (HIGH), LOW on a coil fault.
BRAKE_STATUS_PIN = _pin("PIN_BRAKE_STATUS")
#: The brake's manual-release lever switch (push mode): pulled up (HIGH), LOW when pulled.
PUSH_PIN = _pin("PIN_PUSH")
#: The input pins the control tick reads, by their bit of its ``inputs`` plus one (the
#: numbers of a trace's input changes): the inhibit inputs 1 and 2, the brake's status 3,
#: its manual release 4.
INPUT_PINS = {**INHIBIT_PINS, 3: BRAKE_STATUS_PIN, 4: PUSH_PIN}
# PWM: pin 9 = OC2B on PH6, pin 10 = OC2A on PB4 (Timer2, phase-correct).
_TCCR2A, _OCR2A, _OCR2B = 0xB0, 0xB3, 0xB4
_PWM = {"left": (_OCR2B, 1 << 5, _pin("PIN_PWM_L")), "right": (_OCR2A, 1 << 7, _pin("PIN_PWM_R"))}
_PORT_REG = {"A": 0x22, "B": 0x25, "D": 0x2B, "E": 0x2E, "H": 0x102}
_DDR_REG = {port: address - 1 for port, address in _PORT_REG.items()}


class MegaPins(MegaMemory):
    """The output pins of the Mega a ``VirtualMega`` runs, read from its registers."""

    def pin_output(self, pin: tuple[str, int]) -> int:
        """The level the firmware drives on an output pin (its PORTx bit)."""
        port, bit = pin
        return (self.read_bytes(_PORT_REG[port], 1)[0] >> bit) & 1

    def pwm(self, side: str) -> int:
        """Duty 0..255 on the motor's PWM pin: OCR when the compare output is on,
        else the pin's level (analogWrite 0 and 255 fall back to digitalWrite)."""
        ocr, com_bit, pin = _PWM[side]
        tccr2a = self.read_bytes(_TCCR2A, 1)[0]
        if tccr2a & com_bit:
            return self.read_bytes(ocr, 1)[0]
        return 255 if self.pin_output(pin) else 0

    def direction(self, side: str) -> int:
        """The DIR pin of a motor (1 forward)."""
        return self.pin_output(DIR_PINS[side])

    def relay(self) -> int:
        """The relay pin that powers the motor driver."""
        return self.pin_output(RELAY_PIN)

    def brake_released(self) -> int:
        """1 while the firmware drives the parking brake's pin HIGH as an output (the
        brake released); 0 when it drives it LOW or leaves it an input (at reset: the
        driver's pull-down engages the brake)."""
        port, bit = BRAKE_PIN
        ddr = (self.read_bytes(_DDR_REG[port], 1)[0] >> bit) & 1
        return ddr & self.pin_output(BRAKE_PIN)

    def _named_pins(self) -> dict[str, tuple[str, int]]:
        return {
            "enc_l_a": ENCODER_PINS["left"][0], "enc_l_b": ENCODER_PINS["left"][1],
            "enc_r_a": ENCODER_PINS["right"][0], "enc_r_b": ENCODER_PINS["right"][1],
            "dir_l": DIR_PINS["left"], "dir_r": DIR_PINS["right"], "relay": RELAY_PIN, "brake": BRAKE_PIN,
            "pwm_l_pin": _PWM["left"][2], "pwm_r_pin": _PWM["right"][2],
        }
