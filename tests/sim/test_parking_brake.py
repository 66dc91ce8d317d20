"""A chair with a parking brake drives, and parks on the brake, on both backends.

The firmware owns the brake (``brake_fitted`` 1): released under the hold before the
PID drives, engaged at the first parked tick; the plant's brake follows the pin 50 ms
late. Up and down 1:20 (``ramp_up_down_1in20`` and its ``_brake`` twin): with the brake
the chair climbs as the chair without one does, and once parked it stands within a
millimetre over the last 2 s of each held stop. (That the motors are then unpowered:
tests/sim/test_brake_plant.py.)
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import thorough
from tests.support.grade import alarms, bundled
from wcdrive.firmware import constants as C

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))
STOPS = ((8.0, 9.0), (18.0, 19.0))       # each held stop ends at these (s)


#: On simavr (15 s: both scenarios) at the thorough depth; at the fast one the firmware
#: drives the brake pin in tests/sim/test_fault_hold.py's braked case on simavr
#: (released while driving, engaged at the fault, held), bit for bit as the port.
@pytest.mark.parametrize("backend", BACKENDS if thorough() else ["port"])
def test_a_chair_with_a_brake_drives_and_parks_on_it(backend: str) -> None:
    plain, braked = bundled("ramp_up_down_1in20", backend), bundled("ramp_up_down_1in20_brake", backend)
    for r in (plain, braked):
        assert not alarms(r)
    t = braked.board.tick_time
    up = int(np.searchsorted(t, 4.0))
    # it climbs as the chair without a brake does, the brake's release (the hold's preload
    # and the release time) later: as far at 4 s as the other at 4 s less those ticks
    release_s = 0.05 * (C.BRAKE_PRELOAD_TICKS + C.BRAKE_RELEASE_TICKS)
    late = int(np.searchsorted(plain.board.tick_time, 4.0 - release_s))
    assert braked.truth.pose[up, 0] > 1.0
    assert braked.truth.pose[up, 0] == pytest.approx(plain.truth.pose[late, 0], abs=0.05)
    for start, end in STOPS:
        window = (t >= start - 1.0) & (t < end)
        pose = braked.truth.pose[window, :2]
        assert np.hypot(*(pose - pose[0]).T).max() < 1e-3, (start, end)
