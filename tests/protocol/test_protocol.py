"""protocol/: the generated header is in sync, and the golden vectors pass on both
sides: the Python port and the firmware in simavr.

Each vector runs on a board that has booted and then taken a host's neutral command,
which has stood NEUTRAL_TICKS ticks (protocol/PROTOCOL.md, "Neutral before motion"),
its answers discarded: the same prelude, tick for tick, on both sides (``_prelude_port``,
``_prelude_firmware``). The vector's input comes just past a tick, and its reply is read
before the next one."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from tests.support.boards import boot
from wcdrive.avr.f32 import f32
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware
from wcdrive.protocol import spec as protocol_spec
from wcdrive.protocol.codec import crc16

VECTORS_FILE = Path(__file__).resolve().parents[2] / "protocol" / "vectors.toml"
VECTORS = tomllib.loads(VECTORS_FILE.read_text())["vector"]
MODES = {0: "WHEEL", 1: "CMDVEL", 2: "PPM"}


def test_header_is_generated_from_the_spec() -> None:
    assert protocol_spec.header_path().read_text() == protocol_spec.header()


def test_python_constants_match_the_spec() -> None:
    """Every constant of the spec is in the port's constants, as binary32 for floats."""
    for name, value in protocol_spec.constants().items():
        ours = getattr(C, name)
        assert ours == (f32(value) if isinstance(value, float) else value), name


def _expected(reply: list[str]) -> list[str]:
    """A vector's reply lines with {version} and {build_id} filled in, then {crc}: the
    CRC of a v4 line up to its '*'."""
    lines = [line.replace("{version}", C.FIRMWARE_VERSION).replace("{build_id}", C.BUILD_ID)
             for line in reply]
    return [line.replace("*{crc}", f"*{crc16(line.partition('*')[0].encode()):04X}")
            for line in lines]


def _check(v: dict, reply_lines: list[str], mode: int, right: float, left: float,
           read) -> None:
    assert reply_lines == _expected(v["reply"]), v["name"]
    for name, value in v.get("state", {}).items():
        got = read(name)
        assert got == (f32(value) if isinstance(value, float) else value), (v["name"], name)
    assert MODES[mode] == v["mode"], v["name"]
    assert right == pytest.approx(v["targets"][0], abs=1e-3), v["name"]
    assert left == pytest.approx(v["targets"][1], abs=1e-3), v["name"]


#: The prelude's neutral command: a zero CMDVEL command, the mode a board boots in.
NEUTRAL = b"x:0.000,t:0.000,\n"


def _prelude_port() -> Firmware:
    """The port just past its first tick (as the board after ``boot``), given ``NEUTRAL``,
    and two ticks on: the neutral has stood, just past the second."""
    fw = Firmware()
    fw.tick(C.CONTROL_PERIOD_MS, 0, 0)
    fw.feed(NEUTRAL)
    fw.tick(2 * C.CONTROL_PERIOD_MS, 0, 0)
    fw.tick(3 * C.CONTROL_PERIOD_MS, 0, 0)
    assert fw.state.needNeutral == 0
    return fw


def _prelude_firmware(mega: VirtualMega) -> None:
    """``_prelude_port`` on the firmware: just past the first tick, ``NEUTRAL``, two ticks
    on (just past the second), what the board sent discarded."""
    boot(mega, 0.058)                     # just past the first tick and its lines
    mega.send(NEUTRAL)
    mega.run_for(0.1)                     # the second tick after it, just past
    mega.take_tx()
    assert mega.read("needNeutral") == 0


def _lines(data: bytes) -> list[str]:
    return [line for line in data.decode("latin-1").split("\r\n")
            if line and not line.startswith(("ENC:", "BOOT:"))]


@pytest.mark.parametrize("v", VECTORS, ids=lambda v: v["name"])
def test_vector_on_the_port(v: dict) -> None:
    fw = _prelude_port()
    out = fw.feed(v["input"].encode("latin-1"))
    _check(v, _lines(out), fw.state.mode, fw.state.targetR, fw.state.targetL,
           lambda name: getattr(fw.state, name))


@pytest.mark.simavr
@pytest.mark.parametrize("v", VECTORS, ids=lambda v: v["name"])
def test_vector_on_the_firmware(elf, v: dict) -> None:
    with VirtualMega(elf) as mega:
        _prelude_firmware(mega)
        mega.send(v["input"].encode("latin-1"))
        mega.run_for(0.04)                    # the bytes are in, the next tick not yet
        text = bytes(b for _, b in mega.take_tx())
        _check(v, _lines(text), mega.read("mode"), mega.read("targetR"), mega.read("targetL"),
               mega.read)


def test_codec_parameter_table_matches_the_port() -> None:
    from wcdrive.firmware.params import PARAMS
    from wcdrive.protocol.codec import PARAM_RANGES

    assert list(PARAM_RANGES) == [p.name for p in PARAMS]
    for p in PARAMS:
        low, high = PARAM_RANGES[p.name]
        assert (f32(low), f32(high)) == (f32(p.low), f32(p.high)), p.name
