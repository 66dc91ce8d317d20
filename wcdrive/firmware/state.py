"""The firmware's globals as one plain object.

Field names are those of ``final_control.ino``, so a field of this object and the
SRAM variable of the same name in the ELF can be compared one to one. Floats hold
binary32 values. Tests build any state directly: ``FirmwareState(targetL=2.0, ...)``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields

from wcdrive.firmware import constants as C
from wcdrive.firmware.constants import HIGH, MODE_CMDVEL
from wcdrive.firmware.params import PARAMS, PRESETS, PROFILE_FLOATS

#: The EEPROM parameter block (``EE_BLOCK_BYTES``): the layout version, the float
#: parameters before the drive limits and the profiles' table (4 bytes each),
#: ``watchdog_ms`` (2 bytes), ``feedback_form``, ``brake_fitted`` and ``profile`` (1 byte
#: each) and a CRC-16 (2 bytes).
EE_BLOCK_BYTES = (1 + 4 * (sum(1 for p in PARAMS if not p.integer) - PROFILE_FLOATS)
                  + 4 * len(PRESETS) + 2 + 1 + 1 + 1 + 2)

#: The controller floats compared bit for bit against the firmware's SRAM.
FLOAT_FIELDS = (
    "targetL", "targetR", "setpointL", "setpointR", "rawVelL", "rawVelR", "filtVelL",
    "filtVelR", "integralL", "integralR", "prevMeasL", "prevMeasR", "outputL", "outputR",
    "lastTravel", "pendingL", "pendingR", "haltIntegralL", "haltIntegralR", "haltSetpointL",
    "haltSetpointR", "effortSpeedL", "effortSpeedR", "effortSetpointL",
    "effortSetpointR", "overspeedFromL", "overspeedFromR", "windingTempL", "windingTempR", "supplyVolts",
    "kpL", "kiL", "kdL", "kpR", "kiR", "kdR", "maxWheel", "maxAccel", "estopDecel",
    "fwdSpeed", "revSpeed", "driveAccel", "driveDecel", "turnSpeed", "turnAccel", "turnAtSpeed",
    "tremorDamping", "dampedL", "dampedR", "stallTimeout", "stallTime",
)
#: Integer and flag globals compared exactly.
INT_FIELDS = (
    "mode", "pwmL", "pwmR", "dirL", "dirR", "encTickL", "encTickR", "prevEncL", "prevEncR",
    "lastControlTime", "tickCount", "pivotPhase", "pivotTicksLeft", "cmdSinceTick", "watchdogArmed",
    "lastCmdTime", "emergencyStop", "ppmLost", "stillTicks", "parked", "rejectedCount",
    "errSuppressed", "errLinesThisTick", "cmdLen", "cmdCommas", "cmdDiscarding",
    "illTickL", "illTickR", "watchdogMs", "feedbackForm", "brakeFitted", "profile", "estopLatched",
    "tlmEnabled",
    "linesFramed", "lineCounter", "unframedLine", "lastSeq",
    "rxCount", "crcRejected", "stormTickL", "stormTickR", "faultFlags", "stallTicksL",
    "stallTicksR", "reverseTicksL", "reverseTicksR", "runawayTicksL", "runawayTicksR", "effortPwmL",
    "effortPwmR",
    "effortTicksL", "effortTicksR", "txDropped", "txRingFull", "txCredit", "rxGaps", "rxLostTick",
    "lastTickTime", "lateTicks",
    "eeNext", "eeBusy", "holding", "holdRefL", "holdRefR", "holdStepL", "holdStepR", "holdRollaway",
    "brakeReleased", "brakePhase", "brakeTicks", "brakeStatusTick", "brakeStatusTicks", "overspeedTicksL",
    "overspeedTicksR", "limitLatched",
    "needNeutral", "neutralSeen", "neutralTicks", "notNeutralSent", "notNeutralPending", "notNeutralTicks",
    "neutralFault", "inhibitTick", "inhibitStable", "inhibitCountL", "inhibitCountR", "inhibitCountP",
    "inhibitLatched",
    "inhibitPending", "inhibitOn", "thermalRollback", "thermalPending", "supplyTick", "batteryLow",
    "batteryPending", "currentTickL", "currentTickR",
)

#: Globals the tick takes as inputs rather than computes (loop() measures them).
INPUT_FIELDS = ("freeRam",)


@dataclass(slots=True)
class FirmwareState:
    """The sketch's globals with their initial values (``parked`` 1, ``dirL``/``dirR``
    HIGH, the runtime parameters at the spec's defaults); ``cmdBuf`` holds the command
    being received."""

    mode: int = MODE_CMDVEL
    targetL: float = 0.0
    targetR: float = 0.0
    setpointL: float = 0.0
    setpointR: float = 0.0
    rawVelL: float = 0.0
    rawVelR: float = 0.0
    filtVelL: float = 0.0
    filtVelR: float = 0.0
    integralL: float = 0.0
    integralR: float = 0.0
    haltIntegralL: float = 0.0
    haltIntegralR: float = 0.0
    haltSetpointL: float = 0.0
    haltSetpointR: float = 0.0
    prevMeasL: float = 0.0
    prevMeasR: float = 0.0
    outputL: float = 0.0
    outputR: float = 0.0
    pwmL: int = 0
    pwmR: int = 0
    dirL: int = HIGH
    dirR: int = HIGH
    encTickL: int = 0
    encTickR: int = 0
    prevEncL: int = 0
    prevEncR: int = 0
    illTickL: int = 0
    illTickR: int = 0
    stormTickL: int = 0
    stormTickR: int = 0
    #: The encoder ISRs' storm flags (``stormL``/``stormR``): set by the ISR model
    #: (``wcdrive.firmware.quadrature``) when it masks an encoder, cleared by ``reset``.
    #: ISR-owned, so not compared event by event; the tick's latched copies are.
    stormL: int = 0
    stormR: int = 0
    #: millis() the last tick was due at (ticks run on a fixed 50 ms grid) and ran at
    #: (None: the same as ``lastControlTime``, as ``setup()`` leaves them), and the ticks
    #: that ran more than a period late, restarting the grid.
    lastControlTime: int = 0
    lastTickTime: int | None = None
    lateTicks: int = 0
    tickCount: int = 0
    freeRam: int = 0
    kpL: float = C.KP_L
    kiL: float = C.KI_L
    kdL: float = C.KD_L
    kpR: float = C.KP_R
    kiR: float = C.KI_R
    kdR: float = C.KD_R
    maxWheel: float = C.MAX_WHEEL_SPEED
    maxAccel: float = C.MAX_ACCEL
    estopDecel: float = C.EMERGENCY_DECEL
    #: The drive limits (``wcdrive.firmware.drive``): top speeds forward and back (m/s),
    #: the ramps speeding up and slowing down (m/s^2), the top turn rate (rad/s), how
    #: fast it may change (rad/s^2) and its share left at the top speed.
    fwdSpeed: float = C.DRIVE_SPEED_MAX
    revSpeed: float = C.DRIVE_SPEED_MAX
    driveAccel: float = C.DRIVE_ACCEL_MAX
    driveDecel: float = C.DRIVE_ACCEL_MAX
    turnSpeed: float = C.TURN_SPEED_MAX
    turnAccel: float = C.TURN_ACCEL_MAX
    turnAtSpeed: float = C.TURN_AT_SPEED
    tremorDamping: float = C.TREMOR_DAMPING
    #: The goals the stick's targets give through the tremor damping (``damped_targets``).
    dampedL: float = 0.0
    dampedR: float = 0.0
    watchdogMs: int = C.WATCHDOG_MS
    feedbackForm: int = C.FEEDBACK_FORM
    brakeFitted: int = C.BRAKE_FITTED
    #: The drive profile in force and the profiles' table, row after row
    #: (``wcdrive.firmware.profiles``; the firmware's ``profileTable``, filled by setup()).
    profile: int = C.PROFILE
    profileTable: list[float] = field(default_factory=lambda: list(PRESETS))
    lastTravel: float = 0.0
    pivotPhase: int = 0
    pivotTicksLeft: int = 0
    pendingL: float = 0.0
    pendingR: float = 0.0
    cmdSinceTick: int = 0
    watchdogArmed: int = 0
    lastCmdTime: int = 0
    emergencyStop: int = 0
    ppmLost: int = 0
    stillTicks: int = 0
    parked: int = 1
    #: The hold (``holdError``, ``holdMotor``): on while parked without a fault; each
    #: wheel's reference count and the step it follows while the wheel still slows (0 once
    #: fixed); whether this hold sent ``EVT:ROLLAWAY`` or began braking hardest (an
    #: overspeed, or pushed off while held at the chair's limit).
    holding: int = 0
    holdRefL: int = 0
    holdRefR: int = 0
    holdStepL: int = 0
    holdStepR: int = 0
    holdRollaway: int = 0
    #: The parking brake's pin (``WC_PIN_BRAKE``): HIGH, released. With ``brakeFitted``,
    #: its phase (``wcdrive.firmware.brake``), the ticks in it, the brake driver's status
    #: read LOW this tick (1) and the ticks in a row it has.
    brakeReleased: int = 0
    brakePhase: int = 0
    brakeTicks: int = 0
    brakeStatusTick: int = 0
    brakeStatusTicks: int = 0
    overspeedTicksL: int = 0
    overspeedTicksR: int = 0
    #: ``|prevMeas|`` before the current run of overspeeding ticks began (``overspeedRun``).
    overspeedFromL: float = 0.0
    overspeedFromR: float = 0.0
    #: Each winding's estimated temperature (deg C; ``wcdrive.firmware.thermal``), the
    #: rollback on (``EVT:THERMAL,1`` sent or pending) and its events to send (bit 0 on,
    #: bit 1 off).
    windingTempL: float = C.THERMAL_AMBIENT
    windingTempR: float = C.THERMAL_AMBIENT
    thermalRollback: int = 0
    thermalPending: int = 0
    #: The supply (``wcdrive.firmware.battery``): the ADC count the tick read at
    #: PIN_SUPPLY, the filtered battery voltage (V; 0 until the first tick), the
    #: low-battery rollback on (``EVT:BATTERY,1`` sent or pending) and its events to send
    #: (bit 0 on, bit 1 off).
    supplyTick: int = 0
    supplyVolts: float = 0.0
    batteryLow: int = 0
    batteryPending: int = 0
    #: The motors' currents (``wcdrive.firmware.stall``): the ADC counts the tick read at
    #: PIN_CURRENT_L/R, the stall timeout (s, the parameter ``stall_timeout``) and the
    #: seconds a wheel has been held at its current limit.
    currentTickL: int = C.CURRENT_ZERO_COUNTS
    currentTickR: int = C.CURRENT_ZERO_COUNTS
    stallTimeout: float = C.STALL_TIMEOUT
    stallTime: float = 0.0
    #: Halted at the chair's limit (``EVT:OVERSPEED``, ``EVT:STALLED_ON_GRADE``): motion
    #: refused with ``ERR:limit`` until a stop.
    limitLatched: int = 0
    estopLatched: int = 0
    # neutral before motion: motion refused until a neutral command stood NEUTRAL_TICKS
    needNeutral: int = 1
    neutralSeen: int = 0
    neutralTicks: int = 0
    notNeutralSent: int = 0
    notNeutralPending: int = 0
    notNeutralTicks: int = 0
    neutralFault: int = 0
    # inhibit inputs (bit 0 input 1, bit 1 input 2): read at the tick, debounced, latched,
    # and the events still to send (bit 0/1 input 1 on/off, bit 2/3 input 2)
    inhibitTick: int = 0
    inhibitStable: int = 0
    inhibitCountL: int = 0
    inhibitCountR: int = 0
    inhibitCountP: int = 0
    inhibitLatched: int = 0
    inhibitOn: int = 0
    inhibitPending: int = 0
    faultFlags: int = 0
    stallTicksL: int = 0
    stallTicksR: int = 0
    reverseTicksL: int = 0
    reverseTicksR: int = 0
    runawayTicksL: int = 0
    runawayTicksR: int = 0
    effortPwmL: int = 0
    effortPwmR: int = 0
    effortTicksL: int = 0
    effortTicksR: int = 0
    effortSpeedL: float = 0.0
    effortSpeedR: float = 0.0
    effortSetpointL: float = 0.0
    effortSetpointR: float = 0.0
    tlmEnabled: int = 0
    linesFramed: int = 0
    lineCounter: int = 0
    unframedLine: int = 0
    lastSeq: int = 0
    rxCount: int = 0
    rejectedCount: int = 0
    crcRejected: int = 0
    errSuppressed: int = 0
    errLinesThisTick: int = 0
    #: The output budget (``LineBuffer::send``): bytes that may still be queued, and the
    #: lines dropped for want of it; ``txRingFull`` counts the sketch's second guard.
    txCredit: int = C.TX_CREDIT_BOOT
    txDropped: int = 0
    txRingFull: int = 0
    #: Losses ``loop()`` met in the received bytes (the sum of ``rxGap``'s), and the RX interrupt's
    #: count of lost bytes latched at the last tick (an input, like the encoder counts).
    rxGaps: int = 0
    rxLostTick: int = 0
    #: The EEPROM (``EEPROM_SIZE`` bytes, erased: 0xFF), the block a ``save`` writes and
    #: the next byte of it to write, and whether a save is being written (``wcdrive.firmware.eeprom``).
    eeprom: bytearray = field(default_factory=lambda: bytearray(b"\xff" * C.EEPROM_SIZE))
    eeBlock: bytearray = field(default_factory=lambda: bytearray(EE_BLOCK_BYTES))
    eeNext: int = EE_BLOCK_BYTES
    eeBusy: int = 0
    cmdBuf: bytearray = field(default_factory=bytearray)
    cmdLen: int = 0
    cmdCommas: int = 0
    cmdDiscarding: int = 0
    #: ``WC_BUILD_ID`` (in flash, not a global): the build the port stands for, which the
    #: HELLO line names; a replay takes the board's.
    buildId: str = C.BUILD_ID

    def __post_init__(self) -> None:
        if self.lastTickTime is None:
            self.lastTickTime = self.lastControlTime

    def copy(self) -> FirmwareState:
        """A deep copy."""
        return copy.deepcopy(self)

    def as_dict(self) -> dict[str, object]:
        """Every field by name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
