"""Shared fixtures and the hypothesis profiles.

``default`` is fast, for development; ``ci`` (selected by scripts/test.sh) is the
thorough one: the differential suite then runs at least 200 traces of 5 s each.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

#: The example downstream project has its own tests, run by tests/test_downstream.py
#: in a fresh venv.
collect_ignore = ["downstream"]

settings.register_profile("default", max_examples=20, deadline=None)
settings.register_profile(
    "ci", max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def thorough() -> bool:
    return settings().max_examples >= 200


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
