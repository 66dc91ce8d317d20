"""Every ``wc*://`` handler reads its query through ``url_options``: defaults where
absent, and a wrong scheme, an unknown option or a bad value is a ``SerialException``
that names it."""

from __future__ import annotations

import pytest
import serial

from wcdrive.eddie import serial_url as protocol_wceddie
from wcdrive.transports.urlhandler import protocol_wcavr, protocol_wcsim
from wcdrive.transports.urlhandler.board_serial import LIDAR_DETAILS, url_options


def test_defaults_and_given_values() -> None:
    parts, values, given = url_options("wcsim://?seed=7", "wcsim", protocol_wcsim.USAGE,
                                       protocol_wcsim.OPTIONS)
    assert values == {"speed": 1.0, "seed": 7, "chair": None, "world": None, "start": (0.0, 0.0, 0.0),
                      "lidar": None, **dict.fromkeys(LIDAR_DETAILS)} and given == {"seed"}
    parts, values, given = url_options("wcavr:///tmp/a.elf?plant=0&realtime=false", "wcavr",
                                       protocol_wcavr.USAGE, protocol_wcavr.OPTIONS)
    assert parts.path == "/tmp/a.elf" and values == {"realtime": False, "speed": 1.0, "plant": False,
                                                     "chair": None, "world": None,
                                                     "start": (0.0, 0.0, 0.0), "lidar": None,
                                                     **dict.fromkeys(LIDAR_DETAILS)}
    _, values, _ = url_options("wceddie://?eol=tolerant&speed=2.5", "wceddie", protocol_wceddie.USAGE,
                               protocol_wceddie.OPTIONS)
    assert values == {"speed": 2.5, "seed": 0, "eol": "tolerant"}


@pytest.mark.parametrize(("url", "message"), [
    ("wcavr://?speed=2", r"expected wcsim://\[\?speed=S&seed=N&chair=chair.toml&world=W.*\], got 'wcavr://\?speed=2'"),
    ("wcsim://?colour=red", r"wcsim://: unknown option 'colour' \(wcsim://\[\?speed=S&seed=N&chair=chair.toml&world=W"),
    ("wcsim://?speed=fast", r"wcsim://: speed='fast': could not convert"),
    ("wcsim://?speed=5000", r"speed='5000': speed must be within 0.01 .. 1000"),
    ("wcsim://?seed=1.5", r"seed='1.5'"),
])
def test_bad_queries_name_what_is_wrong(url: str, message: str) -> None:
    with pytest.raises(serial.SerialException, match=message):
        url_options(url, "wcsim", protocol_wcsim.USAGE, protocol_wcsim.OPTIONS)


@pytest.mark.parametrize("url", ["wceddie://?eol=crlf", "wcavr://?realtime=0&speed=3", "wccan://virtual"])
def test_each_handler_refuses_a_bad_url_before_it_starts_a_board(url: str) -> None:
    with pytest.raises(serial.SerialException):
        serial.serial_for_url(url)
