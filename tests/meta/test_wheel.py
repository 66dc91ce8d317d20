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

#: Each builds a wheel: the thorough depth only (scripts/test.sh).
pytestmark = [pytest.mark.simavr, pytest.mark.slow]


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


#: The C helpers setup.py builds at install.
HELPERS = ("wcdrive/avr/_f32_fast", "wcdrive/firmware/_tick_fast", "wcdrive/plant/_chair_kernel",
           "wcdrive/plant/_raycast")
SHIPPED = tuple(h.rsplit("/", 1)[1] + "." for h in HELPERS)
NATIVE_PATHS = ("binary32", "control tick", "plant kernel", "ray cast")


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
                   "wcdrive/plant/csrc/raycast.c", "wcdrive/sim/scenarios/worlds/hospital_corridor.yaml",
                   "wcdrive/sim/scenarios/worlds/hospital_corridor.pgm",
                   "wcdrive/avr/csrc/f32_fast.c", "wcdrive/firmware/csrc/tick_fast.c"):
        assert needed in names, needed
    assert not [n for n in names if "/build/" in n or n.endswith((".o", ".elf"))]
    # the C helpers, built at install, each with its source's hash beside it
    for helper in HELPERS:
        built = [n for n in names if n.startswith(helper + ".") and n.endswith(".so")]
        assert len(built) == 1 and built[0] + ".sha256" in names, (helper, built)


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
    for path in NATIVE_PATHS:
        assert f"  {path}: built at install" in version.stdout, version.stdout
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
             and "wcdrive" in p.parts and not p.name.startswith(SHIPPED)]
    assert built == []                               # builds went to the cache
    assert list(installed["cache"].rglob("final_control.elf"))


def test_without_a_compiler_the_install_succeeds_and_says_so(tmp_path: Path) -> None:
    """A machine with no C compiler at install: the wheel builds and installs with a clear
    message, ships no helper, and wcdrive compiles them on first use where it can."""
    source = checkout_copy(tmp_path / "wcdrive-src")
    env = {**os.environ, "CC": "/bin/false"}
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "-w", str(tmp_path),
                            str(source)], capture_output=True, text=True, env=env)
    assert built.returncode == 0, built.stderr[-2000:]
    said = built.stdout + built.stderr
    assert "not built at install" in said and "apt-get install gcc" in said
    wheel = next(tmp_path.glob("wcdrive-*.whl"))
    assert not [n for n in zipfile.ZipFile(wheel).namelist() if n.endswith(".so")]
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                    str(wheel)], check=True, capture_output=True)
    work = tmp_path / "elsewhere"
    work.mkdir()
    installed = {"venv": venv, "work": work, "cache": tmp_path / "cache"}
    version = _run(installed, str(venv / "bin" / "wcdrive"), "--version")
    for path in NATIVE_PATHS:
        assert f"  {path}: built at first use" in version.stdout, version.stdout
    # and where nothing can be built at all: the Python paths, each saying why
    python = str(venv / "bin" / "python")
    installed["cache"] = tmp_path / "cache2"
    code = ("import os; os.environ['CC'] = '/bin/false'; from wcdrive.avr import f32; "
            "from wcdrive.plant import Plant; from wcdrive.tools.cli import version_text; "
            "p = Plant(); p.advance(5); print(f32.fast is None, p.uses_kernel, f32.mul(0.1, 3.0)); "
            "print(version_text())")
    pure = _run(installed, python, "-c", code)
    assert pure.returncode == 0, pure.stderr
    assert pure.stdout.split()[:3] == ["True", "False", repr(0.30000001192092896)], pure.stdout
    for path in NATIVE_PATHS:
        assert f"  {path}: Python (compiling" in pure.stdout, pure.stdout
    assert "pure Python" in pure.stderr
