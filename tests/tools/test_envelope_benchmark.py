"""``benchmarks/envelope.py --quick`` as a user runs it: the figures come out, the sweep
runs every drive, a healthy chair (with a parking brake or without) latches no fault
inside the envelope nor on a kerb cut, and every encoder, wheel and link fault injected
is found (the dead motor, the slow one, is held only to being found at all)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_quick_envelope_has_no_false_fault_and_finds_the_faults() -> None:
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "envelope.py"), "--quick", "--serial",
                          "--json"], capture_output=True, text=True, check=True, cwd=ROOT, timeout=600)
    figures = json.loads(out.stdout)
    assert figures["errors"] == 0 and figures["runs"] > 100
    healthy, beyond = figures["healthy"]["all"], figures["beyond"]["all"]
    assert healthy["drives"] >= 60 and healthy["fault"] == 0, healthy
    assert healthy["limit_90"] == 0, healthy                  # no limit event within 90 % of rated
    braked = figures["healthy"]["with a brake"]               # a third of the chairs
    assert braked["drives"] >= 10 and braked["fault"] == 0, braked
    # kerb cuts beyond the rated grade: limit events, and at most the known rollback past
    # what the hold carries (ENC_REVERSED after STALLED_ON_GRADE: docs/safety.md, "Not safe
    # yet"; the xfail in tests/sim/test_envelope_property.py)
    assert set(beyond["kinds"]) <= {"ENC_REVERSED_L", "ENC_REVERSED_R"}, beyond
    assert beyond["fault"] <= beyond["drives"] // 6, beyond
    faulty = figures["faulty"]
    for kind in ("encoder_cut", "encoder_reversed", "wheel_locked", "link_cut"):
        assert faulty[kind]["detected"] == faulty[kind]["drives"], (kind, faulty[kind])
        assert faulty[kind]["right_side"] == faulty[kind]["detected"], (kind, faulty[kind])
    assert faulty["motor_dead"]["detected"] > 0
