"""``?chair=chair.toml`` on ``wcsim://`` and ``wcavr://``: the board's plant takes the
file's ``[chair]`` table (``wcdrive.plant.params.load_chair``); a file that is not a
chair file is refused before any board starts, naming what is wrong."""

from __future__ import annotations

from pathlib import Path

import pytest
import serial

from wcdrive.plant.params import ChairFileError, ChairParams, chair_toml, load_chair
from wcdrive.transports.urlhandler import protocol_wcavr, protocol_wcsim
from wcdrive.transports.urlhandler.board_serial import url_options


def _chair(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "chair.toml"
    path.write_text(text)
    return path


def test_a_chair_file_round_trips_through_chair_toml(tmp_path: Path) -> None:
    overrides = {"wheel_inertia": 0.1234567891, "current_limit": 11.0, "counts_per_rev": 4096,
                 "caster_initial_offsets": (0.0, 0.01), "parking_brake": True}
    path = _chair(tmp_path, chair_toml(overrides, {"wheel_inertia": "+- 1 %"}, header="fitted\nby hand"))
    params = load_chair(path)
    assert params.wheel_inertia == 0.1234567891 and params.current_limit == 11.0
    assert params.counts_per_rev == 4096 and isinstance(params.counts_per_rev, int)
    assert params.caster_initial_offsets == (0.0, 0.01) and params.parking_brake is True
    assert params.chair_mass == ChairParams().chair_mass           # the rest stay defaults


@pytest.mark.parametrize(("text", "message"), [
    ("[chair]\nwheel_mass = 3.0\n", "unknown key 'wheel_mass'"),
    ("[chair]\nwheel_inertia = 'heavy'\n", "wheel_inertia = 'heavy' is not a value of float"),
    ("[chair]\ncounts_per_rev = 2500.5\n", "counts_per_rev = 2500.5"),
    ("[chair]\nparking_brake = 1\n", "parking_brake = 1"),
    ("wheel_inertia = 0.1\n", "no \\[chair\\] table"),
    ("[chair\n", "not valid TOML"),
])
def test_a_bad_chair_file_is_refused_by_name(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ChairFileError, match=message):
        load_chair(_chair(tmp_path, text))


def test_sim_url_gives_the_plant_the_chair_file(tmp_path: Path) -> None:
    path = _chair(tmp_path, "[chair]\nviscous_friction = 0.031\nchair_mass = 95.0\n")
    _, values, given = url_options(f"wcsim://?speed=2&chair={path}", "wcsim", protocol_wcsim.USAGE,
                                   protocol_wcsim.OPTIONS)
    assert given == {"speed", "chair"} and values["chair"].viscous_friction == 0.031
    port = serial.serial_for_url(f"wcsim://?chair={path}&speed=5")
    try:
        board = port.board
        assert board.params.viscous_friction == 0.031 and board.plant.p.chair_mass == 95.0
        assert board.plant.s.b == 0.031                 # the plant built from those figures
    finally:
        port.close()
    plain = serial.serial_for_url("wcsim://?speed=5")
    try:
        assert plain.board.plant.p == ChairParams()
    finally:
        plain.close()


def test_avr_url_gives_the_plant_behind_the_pins_the_chair_file(tmp_path: Path, elf: Path) -> None:
    path = _chair(tmp_path, "[chair]\ncurrent_limit = 9.5\n")
    _, values, _ = url_options(f"wcavr://?realtime=0&chair={path}", "wcavr", protocol_wcavr.USAGE,
                               protocol_wcavr.OPTIONS)
    assert values["chair"].current_limit == 9.5 and values["plant"] is True
    board = protocol_wcavr.Serial()._open_board(f"wcavr://{elf}?realtime=0&chair={path}")
    try:
        assert board.plant is not None and board.plant.p.current_limit == 9.5
    finally:
        board.close()


@pytest.mark.parametrize(("url", "message"), [
    ("wcsim://?chair={missing}", r"wcsim://: chair=.*cannot read chair file"),
    ("wcsim://?chair={bad}", r"wcsim://: chair=.*unknown key 'mass'"),
    ("wcavr://?plant=0&chair={good}", r"plant=0 has no chair"),
])
def test_a_bad_chair_option_is_refused_before_a_board_starts(tmp_path: Path, url: str, message: str) -> None:
    good = _chair(tmp_path, "[chair]\ncurrent_limit = 9.5\n")
    bad = tmp_path / "bad.toml"
    bad.write_text("[chair]\nmass = 190\n")
    with pytest.raises(serial.SerialException, match=message):
        serial.serial_for_url(url.format(missing=tmp_path / "none.toml", bad=bad, good=good))
