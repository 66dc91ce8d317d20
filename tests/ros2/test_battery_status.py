"""``/diagnostics``'s ``wcdrive: battery`` status (docs/ros2.md, "Topics"), from the
board's ``TLM:`` line as the host parses it: the supply it measures, OK at a charged
battery, WARN while the low-battery rollback is on (TLM ``state`` bit 7), ERROR once the
cut-off fault latched (docs/safety.md, "The battery")."""

from __future__ import annotations

from wcdrive.protocol.codec import ExtendedTelemetry, parse_line
from wcdrive.ros2.dds import messages


def _tlm(faults: int, state: int, supply_dv: int | None) -> ExtendedTelemetry:
    line = b"TLM:1000,10,3,40,40,1,1,0,0,17,0,0,6577,%d,0,0,%d" % (faults, state)
    if supply_dv is not None:
        line += b",%d" % supply_dv
    tlm = parse_line(line)
    assert isinstance(tlm, ExtendedTelemetry)
    return tlm


def _values(status: dict) -> dict[str, str]:
    return {kv["key"]: kv["value"] for kv in status["values"]}


def test_the_tlm_line_carries_the_supply_and_the_rollback() -> None:
    tlm = _tlm(0, 128 | 1, 228)
    assert tlm.supply_dv == 228 and tlm.supply_v == 22.8
    assert tlm.battery_low and not tlm.thermal_rollback
    older = _tlm(0, 64, None)                  # a board before the field
    assert older.supply_v is None and not older.battery_low and older.thermal_rollback


def test_charged_low_and_cut_off() -> None:
    charged = messages.battery(_tlm(0, 0, 251), "sim://")
    assert charged["name"] == "wcdrive: battery" and charged["level"] == messages.OK
    assert charged["message"] == "25.1 V" and _values(charged)["supply_v"] == "25.1"
    low = messages.battery(_tlm(0, 128, 224), "sim://")
    assert low["level"] == messages.WARN and "22.4 V" in low["message"]
    assert _values(low)["battery_low"] == "True"
    cut = messages.battery(_tlm(0x2000, 128, 205), "sim://")
    assert cut["level"] == messages.ERROR and "20.5 V" in cut["message"]
    # another fault alone is the faults status's, not this one's
    assert messages.battery(_tlm(0x800, 0, 250), "sim://")["level"] == messages.OK
    assert messages.battery(_tlm(0, 0, None), "sim://")["message"] == "not measured"


def test_the_drive_profile_in_force() -> None:
    """``wcdrive: drive profile``: TLM ``state`` bits 8 and 9, by number and by the
    preset's name, beside the other bits (docs/safety.md, "Drive profiles")."""
    tlm = _tlm(0, (2 << 8) | 128, 230)
    assert tlm.drive_profile == 2 and tlm.battery_low
    shown = messages.drive_profile(tlm, "sim://")
    assert shown["name"] == "wcdrive: drive profile" and shown["level"] == messages.OK
    assert shown["message"] == "profile 2 (outdoor)" and _values(shown)["name"] == "outdoor"
    assert messages.drive_profile(_tlm(0, 0, 250), "sim://")["message"] == "profile 0 (open)"
