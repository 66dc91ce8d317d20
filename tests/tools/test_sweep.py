"""``wcdrive sweep``: the spec, the grid, a real ``dask scheduler`` and worker as
processes on localhost (their rows equal a serial run's), Ctrl-C keeping the finished
rows, and one-line errors with their exit statuses."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wcdrive.tools import console, sweep
from wcdrive.tools.cli import main as wcdrive_main

SPEC = """
scenarios = ["step_response", "watchdog"]
seeds = [0, 1]
dt = 0.002
[params]
kp_l = [1.0, 3.0]
"""


def _spec(tmp_path: Path, text: str = SPEC) -> Path:
    path = tmp_path / "spec.toml"
    path.write_text(text)
    return path


def _comparable(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if k not in sweep.WALL_CLOCK_COLUMNS} for r in rows]


def test_grid_and_random_expansion(tmp_path: Path) -> None:
    spec = sweep.load_spec(_spec(tmp_path))
    points = sweep.expand(spec)
    assert len(points) == 2 * 2 * 2
    assert {(p["scenario"], p["seed"], p["params"]["kp_l"]) for p in points} == {
        (s, seed, kp) for s in ("step_response", "watchdog") for seed in (0, 1) for kp in (1.0, 3.0)}
    ranged = SPEC.replace("kp_l = [1.0, 3.0]", "kp_l = { min = 1.0, max = 3.0 }")
    text = 'mode = "random"\nsamples = 5\n' + ranged
    rnd = sweep.load_spec(_spec(tmp_path, text))
    drawn = sweep.expand(rnd)
    assert len(drawn) == 5 and all(1.0 <= p["params"]["kp_l"] <= 3.0 for p in drawn)
    assert drawn == sweep.expand(rnd)                       # the same sample_seed, the same runs


@pytest.mark.parametrize("text, needle", [
    ("scenarios = ['nope']", "no scenario 'nope'"),
    ("scenarios = ['square']\n[params]\nkp = [1]", "unknown [params] kp"),
    ("scenarios = ['square']\n[chair]\nweight = [1]", "unknown [chair] fields weight"),
    ("scenarios = ['square']\n[params]\nkp_l = { min = 1, max = 2 }", "needs mode = \"random\""),
])
def test_bad_specs_give_one_line_and_status_2(tmp_path: Path, capsys, text: str, needle: str) -> None:
    assert wcdrive_main(["sweep", str(_spec(tmp_path, text)), "--serial"]) == console.USAGE
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err


def test_a_run_that_raises_is_a_row_with_its_error(tmp_path: Path) -> None:
    row = sweep.run_one({"run": 0, "scenario": "square", "backend": "port", "seed": 0, "dt": 0.5,
                         "params": {}, "chair": {}})
    assert row["error"].startswith("ValueError: dt must be")


def test_ctrl_c_keeps_the_finished_rows(tmp_path: Path) -> None:
    points = sweep.expand(sweep.load_spec(_spec(tmp_path)))

    def interrupted_after_three(row: dict) -> None:
        if row["run"] == 2:
            raise KeyboardInterrupt

    done, interrupted = sweep.collect(sweep.run_serial(points), on_row=interrupted_after_three)
    assert interrupted and [r["run"] for r in done] == [0, 1, 2]
    out = sweep.write(done, tmp_path / "partial.csv")
    assert [r["run"] for r in sweep.read_csv(out)] == ["0", "1", "2"]


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory: pytest.TempPathFactory):
    """A ``dask scheduler`` and one ``dask worker`` as processes on localhost."""
    pytest.importorskip("distributed")
    info = tmp_path_factory.mktemp("dask") / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).parents[2]),
                                                                      os.environ.get("PYTHONPATH")]))}
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(info)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.read_text().strip():
            assert time.monotonic() < deadline, "the dask scheduler did not start"
            assert procs[0].poll() is None, "the dask scheduler exited"
            time.sleep(0.2)
        import json

        address = json.loads(info.read_text())["address"]
        # its own process group: the nanny and the worker process it starts
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", "1",
                                       "--nthreads", "1", "--no-dashboard"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                                      start_new_session=True))
        from dask.distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(1, timeout=60)
        yield address
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for k, proc in enumerate(procs):
            try:
                # A worker still inside a run (the one the Ctrl-C test left going) cannot
                # stop it: its nanny would wait 8 s before killing it. 2 s, then the group.
                proc.wait(timeout=2 if k else 20)
            except subprocess.TimeoutExpired:
                if k:
                    os.killpg(proc.pid, signal.SIGKILL)
                else:
                    proc.kill()
                proc.wait()


def test_sweep_on_a_real_dask_scheduler_equals_the_serial_run(tmp_path: Path, dask_cluster: str,
                                                              capsys) -> None:
    spec = _spec(tmp_path)
    assert wcdrive_main(["sweep", str(spec), "--scheduler", dask_cluster, "--out",
                         str(tmp_path / "dask.csv"), "--json"]) == 0
    assert '"finished": 8' in capsys.readouterr().out
    assert wcdrive_main(["sweep", str(spec), "--serial", "--out", str(tmp_path / "serial.csv")]) == 0
    on_dask = sweep.read_csv(tmp_path / "dask.csv")
    serial = sweep.read_csv(tmp_path / "serial.csv")
    assert len(on_dask) == len(serial) == 8
    assert _comparable(on_dask) == _comparable(serial)
    # the runs differ (a sweep that ignored its parameters or seeds would not): the gain
    # changes the tracking, the seed the gyro's noise
    assert len({(r["scenario"], r["tracking_rms_rad_s"]) for r in serial}) == 4
    assert len({r["odom_gyro_heading_deg"] for r in serial}) == 8
    assert all(r["error"] == "" for r in serial)


@pytest.mark.simavr
def test_verify_on_a_real_dask_scheduler_equals_the_local_run(dask_cluster: str, elf, capsys) -> None:
    args = ["verify", "--traces", "3", "--seed", "5", "--duration", "0.6", "--elf", str(elf)]
    assert wcdrive_main([*args, "--scheduler", dask_cluster]) == 0
    on_dask = capsys.readouterr().out.strip().splitlines()[-1]
    assert wcdrive_main([*args, "--jobs", "1"]) == 0
    local = capsys.readouterr().out.strip().splitlines()[-1]
    assert on_dask == local and on_dask.startswith("traces=3 ticks=")
    assert "mismatches=0 lost_bytes=0 stalls=0" in on_dask


def test_an_unreachable_scheduler_is_a_connection_failure(tmp_path: Path, capsys,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    # Dask retries a refused connection until the client's timeout (the sweep's 10 s):
    # the same real Client, given 1 s, fails the same way, 9 s sooner.
    from dask import distributed

    client = distributed.Client
    monkeypatch.setattr(distributed, "Client", lambda address, timeout: client(address, timeout="1s"))
    status = wcdrive_main(["sweep", str(_spec(tmp_path)), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert status == console.CONNECTION, err
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in err and err.count("\n") == 1


def test_ctrl_c_on_dask_cancels_the_rest_and_keeps_the_finished(tmp_path: Path, dask_cluster: str) -> None:
    points = sweep.expand(sweep.load_spec(_spec(tmp_path)))
    seen: list[int] = []

    def interrupted_after_two(row: dict) -> None:
        seen.append(row["run"])
        if len(seen) == 2:
            raise KeyboardInterrupt

    start = time.monotonic()
    done, interrupted = sweep.collect(sweep.run_dask(points, scheduler=dask_cluster),
                                      on_row=interrupted_after_two)
    assert interrupted and len(done) == 2 and [r["run"] for r in done] == seen
    assert all(r["error"] == "" for r in done)
    assert time.monotonic() - start < 30
