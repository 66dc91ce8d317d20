"""A digest of a ``wcdrive sim`` port run: a sha256 per field of its ``SimResult``
(every line the board sent with its cycle, the tick log, the plant's motion log, the
gyro's samples, the odometries, every figure; not the wall time), for
tests/sim/test_sim_speed.py's recorded outputs (``tests/data/sim_digests.json``).

Re-record (only when the port's outputs change on purpose, e.g. the firmware's timing):

    WCDRIVE_CACHE=... python tests/support/sim_digest.py tests/data/sim_digests.json
"""

from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

#: The scenarios whose outputs are recorded (short ones, covering resets, silence, a
#: link cut, encoder and plant faults and the edge path's storm guard).
RECORDED = ("fault_reset", "fault_link_cut", "fault_silence", "fault_encoder_cut",
            "fault_encoder_noise_200k", "fault_wheel_locked", "watchdog", "reversal_pivot",
            "l_shape_closed")


def _hash(value: object) -> str:
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value).tobytes() + f"{value.dtype}{value.shape}".encode()
    else:
        data = repr(value).encode()
    return hashlib.sha256(data).hexdigest()[:20]


def digest(result: object) -> dict[str, str]:
    """Field -> hash of a ``SimResult`` (the real-time factor and wall time left out)."""
    out = {key: _hash(value) for key, value in sorted(vars(result).items()) if key != "wall_time"}
    metrics = dict(result.metrics())                         # type: ignore[attr-defined]
    metrics.pop("real_time_factor")
    out["metrics"] = _hash(sorted(metrics.items()))
    return out


def main(path: str) -> None:
    from wcdrive.sim import runner
    from wcdrive.sim.scenario import load

    json.dump({name: digest(runner.run(load(name))) for name in RECORDED}, open(path, "w"), indent=1,
              sort_keys=True)


if __name__ == "__main__":
    main(sys.argv[1])
