"""The backends a test runs on at each depth: the port always, simavr at the fast depth
only for the cases picked as its sample, at the thorough (``ci``) depth for every case.

A case left out at the fast depth is not generated (no skip): the fast depth is a
subset of the thorough one, and CI runs the thorough one. The sample is picked so that
every behaviour the test names still runs on the firmware at the fast depth once."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import pytest

from tests.conftest import thorough


def cases(combos: Iterable[tuple[Any, ...]], ids: Sequence[str],
          fast_simavr: Iterable[str]) -> list[Any]:
    """``pytest.param(*combo, backend)`` for each combo on the port, and on simavr (marked
    ``simavr``) for every combo at the thorough depth, or for those whose id is in
    ``fast_simavr`` at the fast one. Ids: ``<id>-<backend>``."""
    sample = set(fast_simavr)
    combos = list(combos)
    unknown = sample - set(ids)
    assert not unknown, f"sampled cases that do not exist: {sorted(unknown)}"
    out = []
    for combo, name in zip(combos, ids, strict=True):
        out.append(pytest.param(*combo, "port", id=f"{name}-port"))
        if thorough() or name in sample:
            out.append(pytest.param(*combo, "simavr", id=f"{name}-simavr", marks=pytest.mark.simavr))
    return out
