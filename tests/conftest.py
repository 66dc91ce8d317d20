"""Shared fixtures and the hypothesis profiles.

- ``default``: fast, for development and ``bash scripts/test.sh`` on a person's
  machine; the differential suite runs 4 traces of 1.5 s.
- ``ci``: thorough, what ``scripts/test.sh`` runs with ``CI=true``: 200 examples a
  test, the differential suite 2 x 60 traces of 5 s.
- ``explore``: as thorough, with fresh random examples each run and hypothesis'
  example database, to look for new failures (docs/testing.md).

``default`` and ``ci`` are derandomized (each test's examples follow from its name),
so a red run is red again on the same code; ``explore`` prints the seed that replays
it (``--hypothesis-seed``). For that, hypothesis' pool of the project's constants is
taken once, with every library module imported, and held (tests/support/
hypothesis_constants.py): else it grew with what each worker happened to import.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from tests.support.hypothesis_constants import pin_local_constants

#: The example downstream project has its own tests, run by tests/meta/test_downstream.py
#: in a fresh venv.
collect_ignore = ["downstream"]

settings.register_profile("default", max_examples=20, deadline=None, derandomize=True, database=None,
                          print_blob=True)
settings.register_profile(
    "ci", max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow],
    derandomize=True, database=None, print_blob=True,
)
settings.register_profile(
    "explore", max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


@pytest.hookimpl(trylast=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    """Holds hypothesis' pool of the project's constants (in each xdist worker too),
    once the plugins' initialization is over: hypothesis warns if it is taken sooner."""
    pin_local_constants()


def pytest_report_header(config: pytest.Config) -> str:
    profile = settings.get_current_profile_name()
    how = "derandomized" if settings().derandomize else "random examples (replay: --hypothesis-seed)"
    return f"hypothesis profile: {profile} ({settings().max_examples} examples, {how})"


def thorough() -> bool:
    return settings().max_examples >= 200


def pytest_addoption(parser: pytest.Parser) -> None:
    """``--device PATH``: also run the port contract suite (tests/transports/contract/)
    against a real board on that serial device."""
    parser.addoption("--device", default=None, metavar="PATH",
                     help="run tests/transports/contract/ against the board on this serial device "
                          "too (e.g. /dev/ttyACM0)")


# ---- Ctrl-C for the programs the tests start -------------------------------------------
# A test run started in the background by a shell without job control (``cmd &`` in a
# script, nohup) inherits SIGINT ignored, and so would every program a test starts:
# Python then never raises KeyboardInterrupt, and the tests that press Ctrl-C on
# ``wcdrive pty``/``sim``/``bench run`` (test_exit_safety, test_dtr_reset, ...) wait in
# vain. A handler (not an ignore) is reset to the default when a child starts, so the
# children get Ctrl-C back.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


# ---- how much the differential proof covered in this run ---------------------------
# Every lock-step comparison (hil.lockstep.compare: the port against the firmware in
# simavr, whichever test runs it) adds the simulated seconds it compared to the running
# test's user_properties; the summary (on the controller, from every xdist worker's
# reports) prints the total. Wrapped here, before any test module imports compare.
_current: list[pytest.Item] = []


def _count_compared_seconds() -> None:
    from wcdrive.hil import lockstep

    original = lockstep.compare

    def compare(recording: lockstep.Recording) -> lockstep.Report:
        report = original(recording)
        if _current:
            _current[-1].user_properties.append(("differential_s", recording.end_cycle / 16e6))
        return report

    compare.__doc__ = original.__doc__
    lockstep.compare = compare


_count_compared_seconds()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item):
    _current.append(item)
    try:
        return (yield)
    finally:
        _current.pop()


_compared: dict[str, float] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    seconds = sum(v for k, v in report.user_properties if k == "differential_s")
    if seconds and report.when == "call":
        _compared[report.nodeid] = seconds


def pytest_terminal_summary(terminalreporter) -> None:
    if _compared:
        terminalreporter.write_line(
            f"differential (port against firmware, hil.lockstep.compare): {sum(_compared.values()):.0f} "
            f"simulated s in {len(_compared)} tests")


@pytest.fixture(scope="session")
def elf() -> Path:
    from wcdrive.boards.simavr.build import firmware_elf

    return firmware_elf()


@pytest.fixture
def mega(elf: Path):
    from wcdrive.boards.simavr.virtual_mega import VirtualMega

    board = VirtualMega(elf)
    yield board
    board.close()
