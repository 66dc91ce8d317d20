"""A digest of a ``wcdrive sim`` port run: a sha256 per field of its ``SimResult`` and
its records, by the names in ``FIELDS`` (every line the board sent with its cycle, the
tick log, the plant's motion log, the gyro's samples, the odometries, every figure;
not the wall time), for
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


#: The recorded names, each with where its value is in a ``SimResult`` (a record that is
#: None, as ``goal`` in open loop, gives None): the digests keep the names of the fields
#: that ``SimResult`` had before it was grouped into records.
FIELDS = {
    "scenario": "scenario", "backend": "backend", "duration": "duration", "ticks": "ticks",
    "faults": "faults", "fault_at": "fault_at", "stop_at": "stop_at",
    "slope_deg": "terrain.slope_deg", "downhill_heading_deg": "terrain.downhill_heading_deg",
    "ramps": "terrain.ramps",
    "tick_time": "board.tick_time", "tick_cycles": "board.tick_cycles", "setpoint": "board.setpoint",
    "measured": "board.measured", "pwm": "board.pwm", "counts": "board.counts",
    "truth": "truth.pose", "wheel_speed": "truth.wheel_speed", "caster": "truth.caster",
    "caster_scrub_energy": "truth.caster_scrub_energy", "caster_scrub_time": "truth.caster_scrub_time",
    "caster_swivel_work": "truth.caster_swivel_work", "caster_side_impulse": "truth.caster_side_impulse",
    "step_time": "truth.step_time", "step_speed": "truth.step_speed",
    "step_contact_speed": "truth.step_contact_speed", "step_volts": "truth.step_volts",
    "winding_temp": "truth.winding_temp", "battery": "truth.battery",
    "odom_wheel": "odometry.wheel", "odom_velocity": "odometry.velocity", "odom_gyro": "odometry.gyro",
    "odom_ekf": "odometry.ekf", "odom_ekf_vel": "odometry.ekf_vel",
    "gyro_time": "odometry.gyro_time", "gyro_rate": "odometry.gyro_rate",
    "serial_lines": "link.lines", "events": "link.events", "boots": "link.boots", "lines": "link.line_counts",
    "cmd_vel": "link.cmd_vel",
    "goal": "goal.position", "goal_reached_s": "goal.reached_s", "goal_tolerance": "goal.tolerance",
    "steered_by": "goal.steered_by",
    "firmware_differences": "lockstep.differences", "firmware_events_compared": "lockstep.events_compared",
    "world_start": "world.start", "world_segments": "world.segments", "world_circles": "world.circles",
    "collisions": "world.collisions", "first_collision_s": "world.first_collision_s",
    "max_impact_ns": "world.max_impact_ns", "contact_s": "world.contact_s", "contacts": "world.contacts",
    "world_grid": "world.grid", "lidar": "lidar.lidar", "lidar_scans": "lidar.scans",
}


def fields(result: object) -> dict[str, object]:
    """A ``SimResult``'s values by their recorded names (``FIELDS``), in name order."""
    out: dict[str, object] = {}
    for name in sorted(FIELDS):
        value = result
        for attr in FIELDS[name].split("."):
            value = getattr(value, attr)
            if value is None:
                break
        out[name] = value
    return out


def digest(result: object) -> dict[str, str]:
    """Field -> hash of a ``SimResult`` (the real-time factor and wall time left out)."""
    out = {key: _hash(value) for key, value in fields(result).items()}
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
