"""Benchmarks that print figures (docs/benchmarks.md keeps the table).

    python benchmarks/run.py [--quick]

1. Port tick: one whole 50 ms loop period of the port: the bytes of one command
   through processByte, the period's encoder edges decoded in bulk, and controlTick.
2. Closed loop: the port + pymunk plant at 1 kHz vs the firmware in simavr + plant,
   on the same scenario, in this run (real-time factors side by side).
3. Harness: simavr simulated seconds per wall second with both encoders at 28,000
   edges/s each.
4. Protocol v2 host: the same period with a framed (checksummed) command and the TLM
   line on; replay of a recorded session through the port (ticks per wall second).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def bench_port_tick(periods: int, vary: bool = False, v2: bool = False) -> dict[str, float]:
    """``vary``: a different command every period, so the parse cache never helps.
    ``v2``: the command framed with a checksum and the TLM line on (after hello)."""
    from wcdrive.firmware.final_control import Firmware
    from wcdrive.firmware.quadrature import QuadratureDecoder
    from wcdrive.plant.encoders import state_for_count

    fw = Firmware()
    left, right = QuadratureDecoder(), QuadratureDecoder()
    edges = 1400   # 28,000 edges/s for 50 ms on each wheel
    counts = np.arange(1, edges + 1)
    states_r = np.asarray(state_for_count(counts))
    states_l = np.asarray(state_for_count(-counts))
    command = b"x:0.500,t:0.100,"
    if v2:
        from wcdrive.protocol.codec import frame

        fw.feed(b"hello\n")
        command = frame(command, 7)
    samples = []
    now = 0
    for k in range(periods):
        t0 = time.perf_counter()
        fw.feed(f"x:{(k % 2000) * 1e-3:.3f},t:0.100,".encode() if vary else command)
        right.bulk(states_r if k % 2 == 0 else states_r[::-1])
        left.bulk(states_l if k % 2 == 0 else states_l[::-1])
        now += 50
        fw.tick(now, left.count, right.count)
        samples.append(time.perf_counter() - t0)
    return {"median_us": statistics.median(samples) * 1e6,
            "p95_us": float(np.percentile(samples, 95)) * 1e6}


def bench_closed_loop(scenario_name: str, with_simavr: bool) -> dict[str, float]:
    from wcdrive.sim import runner, scenario

    sc = scenario.load(scenario_name)
    port = runner.run(sc, backend="port")
    out = {"scenario_s": sc.duration, "port_rtf": port.real_time_factor}
    if with_simavr:
        sim = runner.run(sc, backend="simavr")
        out["simavr_rtf"] = sim.real_time_factor
        out["ratio"] = port.real_time_factor / sim.real_time_factor
        out["firmware_differences"] = sim.firmware_differences
    return out


def bench_harness(seconds: float) -> dict[str, float]:
    from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
    from wcdrive.plant.encoders import edges_from_trajectory

    mega = VirtualMega()
    rate = 28000.0
    for side, sign in (("left", -1.0), ("right", 1.0)):
        train = edges_from_trajectory(np.array([0.0, 0.01, seconds]),
                                      np.array([0.5, 0.5, 0.5 + sign * rate * (seconds - 0.01)]))
        mega.encoder_edges(side, train)
    t0 = time.perf_counter()
    mega.run_until(int(seconds * F_CPU))
    wall = time.perf_counter() - t0
    counted = (mega.read("encoderValueL"), mega.read("encoderValueR"))
    mega.close()
    return {"sim_s_per_wall_s": seconds / wall, "counts": counted}


def bench_replay(seconds: float) -> dict[str, float]:
    """Records a session on the simulated chair, then times its replay."""
    import serial

    import wcdrive  # noqa: F401  (wcsim://)
    from wcdrive.protocol.codec import frame
    from wcdrive.tools.replay import replay
    from wcdrive.transports.recording import RecordingPort

    port = RecordingPort(serial.serial_for_url("wcsim://?speed=20", timeout=0.05))
    port.write(b"hello\n")
    end = time.monotonic() + seconds / 20
    k = 0
    while time.monotonic() < end:
        port.write(frame(b"x:0.500,t:0.%03d," % (k % 300), k % 65536))
        port.read(65536)
        k += 1
        time.sleep(0.005)
    port.close()
    t0 = time.perf_counter()
    report = replay(port.recording)
    wall = time.perf_counter() - t0
    return {"ticks": report.ticks, "ticks_per_s": report.ticks / wall, "agrees": report.agrees}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="smaller runs")
    parser.add_argument("--no-simavr", action="store_true")
    args = parser.parse_args()
    tick = bench_port_tick(200 if args.quick else 2000)
    print(f"port tick (50 ms period, the host's 16-byte command, 2 x 1400 edges in bulk): "
          f"median {tick['median_us']:.1f} us, p95 {tick['p95_us']:.1f} us  (target <= 50 us)")
    new = bench_port_tick(200 if args.quick else 2000, vary=True)
    print(f"port tick, a different command every period: median {new['median_us']:.1f} us, "
          f"p95 {new['p95_us']:.1f} us")
    v2 = bench_port_tick(200 if args.quick else 2000, v2=True)
    print(f"port tick, v2 host (framed command, TLM line on): median {v2['median_us']:.1f} us, "
          f"p95 {v2['p95_us']:.1f} us")
    rp = bench_replay(5.0 if args.quick else 30.0)
    print(f"replay of a recorded session through the port: {rp['ticks']} ticks, "
          f"{rp['ticks_per_s']:.0f} ticks per wall s (agrees: {rp['agrees']})")
    loop = bench_closed_loop("square" if args.quick else "corridor_100m", False)
    print(f"closed loop port + plant at 1 kHz, {loop['scenario_s']:.0f} s scenario: "
          f"{loop['port_rtf']:.0f}x real time  (target >= 200x)")
    if not args.no_simavr:
        both = bench_closed_loop("step_response", True)
        print(f"same run, step_response ({both['scenario_s']:.1f} s): port + plant {both['port_rtf']:.0f}x, "
              f"simavr + plant {both['simavr_rtf']:.2f}x real time, ratio {both['ratio']:.0f}; "
              f"firmware output differences {both['firmware_differences']}")
        h = bench_harness(1.0 if args.quick else 3.0)
        print(f"simavr harness, two encoders at 28,000 edges/s: {h['sim_s_per_wall_s']:.2f} simulated s "
              f"per wall s (counts {h['counts']})")


if __name__ == "__main__":
    main()
