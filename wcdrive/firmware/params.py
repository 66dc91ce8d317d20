"""The runtime parameters of protocol v2 (``get:<name>`` / ``set:<name>=<value>``): their
names, the state fields they live in and their ranges, in the firmware's table order."""

from __future__ import annotations

from dataclasses import dataclass

from wcdrive.firmware import constants as C


@dataclass(frozen=True)
class Param:
    name: str          # as on the wire
    field: str         # FirmwareState field (the firmware global of the same name)
    low: float
    high: float
    integer: bool = False


PARAMS: tuple[Param, ...] = (
    Param("kp_l", "kpL", 0.0, C.GAIN_P_MAX),
    Param("ki_l", "kiL", C.GAIN_I_MIN, C.GAIN_I_MAX),
    Param("kd_l", "kdL", 0.0, C.GAIN_D_MAX),
    Param("kp_r", "kpR", 0.0, C.GAIN_P_MAX),
    Param("ki_r", "kiR", C.GAIN_I_MIN, C.GAIN_I_MAX),
    Param("kd_r", "kdR", 0.0, C.GAIN_D_MAX),
    Param("max_wheel", "maxWheel", C.MAX_WHEEL_MIN, C.MAX_WHEEL_SPEED),
    Param("max_accel", "maxAccel", C.ACCEL_MIN, C.ACCEL_MAX),
    Param("estop_decel", "estopDecel", C.DECEL_MIN, C.DECEL_MAX),
    Param("watchdog_ms", "watchdogMs", C.WATCHDOG_MIN_MS, C.WATCHDOG_MAX_MS, integer=True),
)
BY_NAME: dict[bytes, int] = {p.name.encode(): i for i, p in enumerate(PARAMS)}
