"""The command line's failures: one line on stderr (a traceback only with --debug) and
an exit status per kind of failure (wcdrive.tools.console)."""

from __future__ import annotations

import argparse

import pytest

from wcdrive._util.native import BuildError
from wcdrive.errors import WcdriveEstopError, WcdriveProtocolError, WcdriveTimeoutError
from wcdrive.tools import cli, console


def test_unknown_scenario_is_one_line_and_status_2(capsys) -> None:
    assert cli.main(["sim", "no_such_scenario", "--no-plots"]) == console.USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("wcdrive sim: no scenario 'no_such_scenario'")


def test_a_device_that_is_not_there_is_a_connection_failure(capsys) -> None:
    status = cli.main(["can-gateway", "--chair", "/dev/wcdrive-no-such-device", "--interface", "virtual",
                       "--channel", "x", "--seconds", "0.1"])
    err = capsys.readouterr().err
    assert status == console.CONNECTION, err
    assert err.count("\n") == 1 and "Traceback" not in err and "/dev/wcdrive-no-such-device" in err


def _raising(exc: BaseException):
    def func(args: argparse.Namespace) -> int:
        raise exc
    return func


@pytest.mark.parametrize("exc, status", [
    (WcdriveTimeoutError("the board did not answer"), console.TIMEOUT),
    (WcdriveProtocolError("speaks v1"), console.PROTOCOL),
    (WcdriveEstopError("e-stop latched", "estop"), console.COMMAND),
    (BuildError("avr-gcc is missing: apt-get install gcc-avr"), console.BUILD),
    (KeyboardInterrupt(), console.INTERRUPTED),
    (RuntimeError("a bug"), console.INTERNAL),
])
def test_each_failure_class_has_its_status(monkeypatch, capsys, exc: BaseException, status: int) -> None:
    monkeypatch.setattr(cli, "_sim", _raising(exc))
    assert cli.main(["sim", "square"]) == status
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert len(set(console.EXIT_CODES.values())) == len(console.EXIT_CODES)


def test_debug_shows_the_traceback(monkeypatch, capsys) -> None:
    monkeypatch.setattr(cli, "_sim", _raising(RuntimeError("a bug")))
    assert cli.main(["sim", "square"]) == console.INTERNAL
    assert "--debug" in capsys.readouterr().err
    assert cli.main(["--debug", "sim", "square"]) == console.INTERNAL
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "RuntimeError: a bug" in err
