"""``/diagnostics``'s ``wcdrive: motor heat`` status (docs/ros2.md, "Topics"), from the
board's ``TLM:`` line as the host parses it: OK when cool, WARN while the thermal
rollback is on (TLM ``state`` bit 6), ERROR once a winding's cut-off fault latched
(docs/safety.md, "Motor heat")."""

from __future__ import annotations

from wcdrive.protocol.codec import ExtendedTelemetry, parse_line
from wcdrive.ros2.dds import messages


def _tlm(faults: int, state: int) -> ExtendedTelemetry:
    line = b"TLM:1000,10,3,40,40,1,1,0,0,17,0,0,6585,%d,0,0,%d" % (faults, state)
    tlm = parse_line(line)
    assert isinstance(tlm, ExtendedTelemetry)
    return tlm


def _values(status: dict) -> dict[str, str]:
    return {kv["key"]: kv["value"] for kv in status["values"]}


def test_cool_hot_and_cut_off() -> None:
    cool = messages.motor_heat(_tlm(0, 0), "sim://")
    assert cool["name"] == "wcdrive: motor heat" and cool["level"] == messages.OK
    hot = messages.motor_heat(_tlm(0, 64 | 1), "sim://")
    assert hot["level"] == messages.WARN and "rollback" in hot["message"]
    assert _values(hot)["thermal_rollback"] == "True"
    cut = messages.motor_heat(_tlm(0x1000 | 0x800, 64), "sim://")
    assert cut["level"] == messages.ERROR and _values(cut)["cut_off"] == "OVERHEAT_L,OVERHEAT_R"
    # another fault alone is the faults status's, not this one's
    assert messages.motor_heat(_tlm(0x80, 0), "sim://")["level"] == messages.OK
