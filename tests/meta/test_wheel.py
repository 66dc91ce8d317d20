"""The wheel is self-contained: ``pip install <checkout>`` (not editable) into a fresh
venv, used from a folder outside the checkout, runs the simavr backend, the
differential check and the URL handlers; its only top-level name is ``wcdrive`` (plus
the URL-handler hook), and builds go to the per-user cache, never into site-packages.
"""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.support.checkout import checkout_copy

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.simavr


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("wheel")
    source = checkout_copy(root / "wcdrive-src")      # the build writes nothing into the checkout
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(root), str(source)],
                   check=True, capture_output=True)
    wheel = next(root.glob("wcdrive-*.whl"))
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q",
                    "--disable-pip-version-check", str(wheel)], check=True, capture_output=True)
    work = root / "elsewhere"
    work.mkdir()
    return {"wheel": wheel, "venv": venv, "work": work, "cache": root / "cache"}


def _run(installed: dict[str, Path], *args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["WCDRIVE_CACHE"] = str(installed["cache"])
    env["PATH"] = f"{installed['venv'] / 'bin'}:{env['PATH']}"
    return subprocess.run(list(args), capture_output=True, text=True, cwd=installed["work"], env=env,
                          timeout=timeout)


def test_the_wheel_installs_only_wcdrive_and_the_url_hook(installed: dict[str, Path]) -> None:
    names = zipfile.ZipFile(installed["wheel"]).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"wcdrive", "_wcdrive_serial_urls.py", "wcdrive-serial-urls.pth"}
    for needed in ("wcdrive/py.typed", "wcdrive/hil/lockstep.py", "wcdrive/_data/protocol/spec.toml",
                   "wcdrive/_data/protocol/vectors.toml", "wcdrive/_data/protocol/wcdrive.dbc",
                   "wcdrive/_data/firmware/final_control/final_control.ino",
                   "wcdrive/_data/firmware/final_control/Makefile",
                   "wcdrive/boards/simavr/csrc/wcsim.c", "wcdrive/plant/csrc/chair_kernel.c",
                   "wcdrive/avr/csrc/f32_fast.c", "wcdrive/firmware/csrc/tick_fast.c"):
        assert needed in names, needed
    assert not [n for n in names if "/build/" in n or n.endswith((".o", ".elf", ".so"))]


def test_imports_outside_the_checkout(installed: dict[str, Path]) -> None:
    python = str(installed["venv"] / "bin" / "python")
    assert _run(installed, python, "-c", "import hil").returncode != 0
    code = ("import wcdrive, wcdrive.hil, pathlib, importlib.resources as r; "
            "p = pathlib.Path(wcdrive.__file__).parent; "
            "assert 'site-packages' in str(p), p; assert (p / 'py.typed').exists(); "
            "assert r.files('wcdrive._data.protocol').joinpath('spec.toml').is_file(); "
            "from wcdrive.avr import f32; from wcdrive.firmware import tick_fast; "
            "assert f32.fast is not None and tick_fast.fast is not None; "
            "import serial; s = serial.serial_for_url('wcsim://?speed=4', timeout=1); "
            "assert b'ENC:' in s.read(200); s.close(); print('ok')")
    result = _run(installed, python, "-c", code)
    assert result.stdout.strip() == "ok", result.stderr


def test_version_and_every_help(installed: dict[str, Path]) -> None:
    wcdrive = str(installed["venv"] / "bin" / "wcdrive")
    version = _run(installed, wcdrive, "--version")
    assert version.returncode == 0 and "wcdrive 0." in version.stdout and "protocol v" in version.stdout
    for command in (["sim"], ["verify"], ["bench"], ["bench", "flash"], ["bench", "run"],
                    ["bench", "record"], ["bench", "replay"], ["bench", "plot"], ["pty"], ["can-gateway"]):
        result = _run(installed, wcdrive, *command, "--help")
        assert result.returncode == 0 and "usage: wcdrive" in result.stdout, (command, result.stderr)


def test_simavr_backend_and_verify_from_the_wheel(installed: dict[str, Path]) -> None:
    wcdrive = str(installed["venv"] / "bin" / "wcdrive")
    sim = _run(installed, wcdrive, "sim", "step_response", "--backend", "simavr", "--no-plots", "--json")
    assert sim.returncode == 0, sim.stderr
    assert '"firmware_differences": 0' in sim.stdout
    verify = _run(installed, wcdrive, "verify", "--traces", "3", "--seed", "1")
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert "mismatches=0 lost_bytes=0 stalls=0" in verify.stdout.strip().splitlines()[-1]
    site = installed["venv"] / "lib"
    built = [p for p in site.rglob("*") if p.suffix in (".o", ".elf", ".hex", ".so", ".a")
             and "wcdrive" in p.parts]
    assert built == []                               # builds went to the cache
    assert list(installed["cache"].rglob("final_control.elf"))
