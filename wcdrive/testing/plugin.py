"""The pytest plugin (entry point ``pytest11``: ``wcdrive = wcdrive.testing.plugin``).

Installing wcdrive makes these fixtures available to every test suite, with no
``conftest.py``:

- ``wc_chair``: a ``wcdrive.Wheelchair`` on ``sim://`` (the port and the plant in this
  process, paced at ``--wc-speed`` times the wall clock, 10 by default), closed (and so
  stopped) after the test.
- ``wc_simavr_chair``: the same on ``simavr://``, the compiled firmware in simavr.
  Skipped, with the reason (the ``apt-get install`` line), when avr-gcc or libsimavr
  is missing.
- ``wc_port``: a ``wcdrive.testing.SteppedChair``: the port and the plant, no thread,
  advanced by the test (``wc_port.run(seconds)``).
- ``wc_faulty_port``: a factory, ``wc_faulty_port(Fault(...), ...)`` or
  ``wc_faulty_port("encoder_cut", at=1.0, side="left")``, giving a ``SteppedChair``
  with those faults injected.

The plugin imports wcdrive only when a fixture is used, so it costs a test run
nothing otherwise.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from wcdrive.host.wheelchair import Wheelchair
    from wcdrive.testing.stepped import SteppedChair


def pytest_addoption(parser: pytest.Parser) -> None:
    """``--wc-speed``: how fast ``wc_chair``'s simulation runs."""
    group = parser.getgroup("wcdrive", "wcdrive's simulated chair")
    group.addoption("--wc-speed", type=float, default=10.0,
                    help="wc_chair: simulated time per wall time (default 10)")


def simavr_missing() -> str | None:
    """Why ``simavr://`` cannot run here (None: it can): builds the firmware and the
    harness into the cache if needed."""
    from wcdrive.boards.simavr.build import BuildError, firmware_elf, harness_library

    try:
        harness_library()
        firmware_elf()
    except (BuildError, OSError) as exc:
        return f"simavr:// needs the AVR toolchain and libsimavr: {exc}"
    return None


@pytest.fixture
def wc_chair(request: pytest.FixtureRequest) -> Iterator[Wheelchair]:
    """A ``sim://`` chair, closed after the test."""
    import wcdrive

    speed = request.config.getoption("--wc-speed")
    with wcdrive.connect(f"sim://?speed={speed:g}") as chair:
        assert isinstance(chair, wcdrive.Wheelchair)
        yield chair


@pytest.fixture
def wc_simavr_chair() -> Iterator[Wheelchair]:
    """A ``simavr://`` chair (the compiled firmware), closed after the test; skipped
    when the toolchain is missing."""
    reason = simavr_missing()
    if reason:
        pytest.skip(reason)
    import wcdrive

    with wcdrive.connect("simavr://") as chair:
        assert isinstance(chair, wcdrive.Wheelchair)
        yield chair


@pytest.fixture
def wc_port() -> SteppedChair:
    """The port and the plant, stepped by the test: ``wc_port.run(seconds)``."""
    from wcdrive.testing.stepped import SteppedChair

    return SteppedChair()


@pytest.fixture(scope="session")
def wc_faulty_port() -> Callable[..., SteppedChair]:
    """A factory of ``SteppedChair`` with faults: ``wc_faulty_port(*faults)`` with
    ``Fault`` objects, or ``wc_faulty_port(kind, at=..., side=..., ...)`` for one.
    Each call makes a new chair, so the factory is session-scoped and safe to use
    from a hypothesis ``@given`` test."""
    from wcdrive.plant.faults import Fault
    from wcdrive.testing.stepped import SteppedChair

    def make(*faults: Any, **fault: Any) -> SteppedChair:
        if faults and isinstance(faults[0], str):
            items = [Fault(kind=faults[0], **fault)]
        else:
            items = list(faults)
            if fault:
                raise TypeError("give Fault objects, or one kind with its fields as keywords")
        return SteppedChair(faults=items)

    return make
