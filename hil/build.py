"""Builds what the harness needs from source: libwcsim.so and the firmware ELF.

Nothing prebuilt is shipped. ``harness_library()`` compiles ``hil/csrc/wcsim.c``
against Debian's libsimavr 1.6 into a cache directory keyed by the source's hash;
``firmware_elf()`` runs the firmware's Makefile. Both raise ``BuildError`` with the
command to install what is missing.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

HIL_DIR = Path(__file__).resolve().parent
REPO_DIR = HIL_DIR.parent
HARNESS_SOURCE = HIL_DIR / "csrc" / "wcsim.c"
FIRMWARE_DIR = REPO_DIR / "firmware" / "final_control"
DEBIAN_PACKAGES = "gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev libelf-dev"


class BuildError(RuntimeError):
    """A build step failed; the message says what to install or run."""


def cache_dir() -> Path:
    base = os.environ.get("WCDRIVE_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "wcdrive"
    )
    path = Path(base)
    path.mkdir(parents=True, exist_ok=True)
    return path


def harness_library() -> Path:
    """Path of libwcsim.so, compiled now if the source changed since the last build."""
    source = HARNESS_SOURCE.read_bytes()
    digest = hashlib.sha256(source).hexdigest()[:16]
    target = cache_dir() / f"libwcsim-{digest}.so"
    if target.exists():
        return target
    if not Path("/usr/include/simavr/sim_avr.h").exists():
        raise BuildError(
            "libsimavr headers are missing: apt-get install libsimavr-dev libelf-dev"
        )
    cc = os.environ.get("CC", "gcc")
    tmp = target.with_suffix(f".{os.getpid()}.tmp")
    cmd = [cc, "-shared", "-fPIC", "-O2", "-Wall", "-o", str(tmp), str(HARNESS_SOURCE),
           "-lsimavr", "-lelf"]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise BuildError(f"compiling the simavr harness failed:\n{' '.join(cmd)}\n{result.stderr}")
    os.replace(tmp, target)
    return target


def firmware_elf(sketch_dir: Path = FIRMWARE_DIR) -> Path:
    """Builds a sketch folder (default firmware/final_control) with the firmware's
    Makefile; a no-op when up to date. Returns the ELF's path."""
    if shutil.which("avr-gcc") is None:
        raise BuildError(f"avr-gcc is missing: apt-get install {DEBIAN_PACKAGES}")
    sketch = sketch_dir.name
    cmd = ["make", "-s", "-C", str(sketch_dir), "-f", str(FIRMWARE_DIR / "Makefile"),
           f"SKETCH={sketch}", f"build/{sketch}.elf"]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise BuildError(f"building {sketch} failed:\n{result.stdout}\n{result.stderr}")
    return sketch_dir / "build" / f"{sketch}.elf"


FPCHECK_DIR = REPO_DIR / "firmware" / "fpcheck"
