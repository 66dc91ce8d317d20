"""What ``wcdrive sim`` prints and draws: a table, JSON, and PNG plots."""

from __future__ import annotations

import json
import math
from pathlib import Path

from wcdrive.sim.result import SimResult, placed


def table(result: SimResult) -> str:
    """What ``wcdrive sim`` prints for a run: ground truth against the three odometries,
    tracking error, caster work, the board's line counts, (simavr backend) the
    differences between the port and the firmware, the floor when it is not level, the
    start pose and the collisions with the walls when the scenario has them, the lidar
    and its scans, the figures after a fault and after the last stop, and the board's
    events."""
    m = result.metrics()
    rows = [
        ("", "x (m)", "y (m)", "heading (deg)", "pos. error (m)", "heading error (deg)"),
        ("ground truth", f"{m['truth_x']:.3f}", f"{m['truth_y']:.3f}",
         f"{m['truth_heading_deg']:.2f}", "", ""),
    ]
    for key, label in (("odom_wheel", "wheel odometry (position)"),
                       ("odom_velocity", "wheel odometry (velocity)"),
                       ("odom_gyro", "wheels + gyro heading"),
                       ("odom_ekf", "EKF, seed 000 (wheels x, y, vx)"),
                       ("odom_ekf_vel", "EKF, wheel velocities")):
        if key + "_x" not in m:
            continue
        rows.append((label, f"{m[key + '_x']:.3f}", f"{m[key + '_y']:.3f}", f"{m[key + '_heading_deg']:.2f}",
                     f"{m[key + '_position_error_m']:.4f}", f"{m[key + '_heading_error_deg']:.3f}"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = [f"scenario {result.scenario} ({result.backend}): {result.duration:.1f} s simulated, "
             f"{result.ticks} ticks, {result.real_time_factor:.0f}x real time"]
    for r in rows:
        lines.append("  " + "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in
                                      enumerate(zip(r, widths, strict=True))))
    lines.append("  wheel speed tracking error (rms, setpoint - filtered): "
                 f"{m['tracking_rms_rad_s']:.3f} rad/s")
    lines.append(f"  casters: swivel work {m['caster_swivel_work_j']:.2f} J, side push "
                 f"{m['caster_side_impulse_ns']:.1f} N s, scrub {m['caster_scrub_energy_j']:.3f} J")
    lines.append(f"  lines from the board: {m['lines_feedback']} feedback, {m['lines_error']} ERR, "
                 f"{m['lines_event']} EVT")
    if result.lockstep is not None:
        lines.append(f"  port vs firmware: {result.lockstep.differences} differences over "
                     f"{result.lockstep.events_compared} firmware events")
    lines.append(f"  control ticks: at most {m['max_tick_gap_ms']:.1f} ms apart")
    if m.get("closed_loop"):
        reached = m["goal_reached_s"]
        lines.append(f"  closed loop ({m['steered_by']} odometry): "
                     f"goal ({m['goal_x']:.2f}, {m['goal_y']:.2f}) "
                     + (f"reached at {reached:.2f} s" if reached is not None else "never reached")
                     + f", true error {m['goal_error_m']:.3f} m (tolerance {m['goal_tolerance_m']:.2f} m: "
                     + ("within" if m["goal_within_tolerance"] else "NOT within") + ")")
    for fault in result.faults:
        what = fault.kind + (f" {fault.side}" if fault.side else "")
        what += f" at {fault.at:g} s" + (f" for {fault.duration:g} s" if fault.duration else "")
        if fault.rate_hz:
            what += f", {fault.rate_hz:g} edges/s"
        lines.append(f"  fault: {what}")
    if m["fault_at_s"] is not None:
        def secs(key: str) -> str:
            v = m[key]
            return "never" if v is None else f"{v:.3f} s"
        lines.append(f"  after the fault ({m['fault_at_s']:.3f} s): PWM 0 after "
                     f"{secs('pwm_zero_after_fault_s')}, standstill after "
                     f"{secs('standstill_after_fault_s')}, travel {m['travel_after_fault_m']:.3f} m, "
                     f"peak {m['peak_speed_after_fault_mps']:.3f} m/s")
    terrain = result.terrain
    if not terrain.flat:
        floor = f"{terrain.slope_deg:g} deg toward {terrain.downhill_heading_deg:g} deg"
        floor += "".join(f", {r.slope_deg:g} deg from {r.from_x:g} to {r.to_x:g} m" for r in terrain.ramps)
        lines.append(f"  floor: {floor}")
    world = result.world
    if world is not None:
        x0, y0, th0 = world.start
        text = f"  world: start ({x0:.3f}, {y0:.3f}, {math.degrees(th0):.1f} deg)"
        if world.walled:
            first = world.first_collision_s
            text += (f", {world.collisions} collision{'' if world.collisions == 1 else 's'}"
                     + ("" if first is None else f", the first at {first:.3f} s, the largest impact "
                        f"{world.max_impact_ns:.1f} N s, {world.contact_s:.3f} s touching"))
        lines.append(text)
        for c in world.contacts[:10]:
            lines.append(f"  {c.time:8.3f} s  collision at ({c.x:.3f}, {c.y:.3f}), impact "
                         f"{c.impact:.1f} N s, {c.duration:.3f} s touching")
    if result.lidar is not None:
        lidar, scans = result.lidar.lidar, result.lidar.scans
        mount = lidar.mount
        beams = sorted({len(scan.ranges) for scan in scans})
        lines.append(f"  lidar: {lidar.model.name} at ({mount.x:.2f}, {mount.y:.2f}, {mount.z:.2f}) m, "
                     f"yaw {mount.yaw_deg:g} deg" + (", head down" if mount.inverted else "")
                     + f", {len(scans)} scans of {'/'.join(str(b) for b in beams) or 0} beams")
    stop = result.stop_metrics()
    if stop["stop_at_s"] is not None:
        drift = stop["drift_parked_m"]
        rest = "never at rest" if stop["rest_at_s"] is None else (
            f"at rest after {stop['stopping_time_s']:.3f} s and {stop['stopping_distance_m']:.3f} m")
        lines.append(f"  after the stop ({stop['stop_at_s']:.3f} s): {rest}, top speed "
                     f"{stop['max_speed_after_stop_mps']:.3f} m/s, travel "
                     f"{stop['travel_after_stop_m']:.3f} m, parked drift "
                     + ("-" if drift is None else f"{drift:.3f} m"))
    for t, line in result.link.boots[1:] + result.link.events:
        lines.append(f"  {t:8.3f} s  {line}")
    return "\n".join(lines)


def to_json(results: list[SimResult]) -> str:
    """The metrics of ``results`` as a JSON list (NaN and inf as null)."""

    def clean(v):
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if hasattr(v, "item"):
            v = v.item()
        if isinstance(v, float):
            return None if math.isnan(v) or math.isinf(v) else round(v, 6)
        return v

    return json.dumps([{k: clean(v) for k, v in r.metrics().items()} for r in results], indent=2)


def plots(result: SimResult, out: Path) -> list[Path]:
    """Writes trajectory.png, wheels.png and pwm.png into ``out`` (created); returns
    their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    board, truth, odometry = result.board, result.truth, result.odometry
    t = board.tick_time
    paths = []

    fig, ax = plt.subplots(figsize=(6.5, 6))
    wheel, gyro, world = odometry.wheel, odometry.gyro, result.world
    if world is not None:
        wheel, gyro = placed(world.start, wheel), placed(world.start, gyro)
        for x0, y0, x1, y1 in world.segments:
            ax.plot([x0, x1], [y0, y1], "-", color="0.4", lw=1)
        for cx, cy, r in world.circles:
            ax.add_patch(plt.Circle((cx, cy), r, color="0.4"))
        for c in world.contacts:
            ax.plot(c.x, c.y, "rx")
    ax.plot(truth.pose[:, 0], truth.pose[:, 1], "k-", lw=2, label="ground truth")
    ax.plot(wheel[:, 0], wheel[:, 1], "C0--", label="wheel odometry")
    ax.plot(gyro[:, 0], gyro[:, 1], "C2:", lw=2, label="wheels + gyro")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{result.scenario}: trajectory")
    ax.grid(True, alpha=0.3)
    ax.legend()
    paths.append(_save(fig, out / "trajectory.png"))

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for i, side in enumerate(("left", "right")):
        a = axes[i]
        a.plot(t, board.setpoint[:, i], "k-", label="setpoint (ramped)")
        a.plot(t, board.measured[:, i], "C0-", label="measured (filtered)")
        a.plot(t, truth.wheel_speed[:, i], "C1--", lw=1, label="true wheel speed")
        a.set_ylabel(f"{side} wheel (rad/s)")
        a.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[1].set_xlabel("time (s)")
    axes[0].set_title(f"{result.scenario}: wheel speeds")
    paths.append(_save(fig, out / "wheels.png"))

    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.step(t, board.pwm[:, 0], where="post", label="left")
    ax.step(t, board.pwm[:, 1], where="post", label="right")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("PWM duty, signed by DIR")
    ax.set_ylim(-260, 260)
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title(f"{result.scenario}: motor commands")
    paths.append(_save(fig, out / "pwm.png"))
    return paths


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
