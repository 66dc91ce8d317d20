"""Builds what the simulated Mega needs from source: the harness library and the
firmware ELF.

Nothing prebuilt is shipped, and nothing is built inside the installed package.
``harness_library()`` compiles ``csrc/wcsim.c`` (beside this module) against Debian's
libsimavr 1.6; ``firmware_elf()`` runs the firmware's own Makefile on the sketch
folder (``wcdrive._util.resources.firmware_dir()``) with its build folder in the per-user
cache. Both raise ``BuildError`` with the command that installs what is missing.
"""

from __future__ import annotations

import fcntl
import hashlib
import shutil
import subprocess
from pathlib import Path

from wcdrive._util.native import BuildError, compile_shared
from wcdrive._util.resources import cache_dir, firmware_dir

__all__ = ["DEBIAN_PACKAGES", "BuildError", "firmware_elf", "harness_library"]

HARNESS_SOURCE = Path(__file__).resolve().parent / "csrc" / "wcsim.c"
DEBIAN_PACKAGES = "gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev libelf-dev"


def harness_library() -> Path:
    """Path of libwcsim.so, compiled now if the source changed since the last build."""
    if not Path("/usr/include/simavr/sim_avr.h").exists():
        raise BuildError("libsimavr headers are missing: apt-get install libsimavr-dev libelf-dev")
    return compile_shared(HARNESS_SOURCE, "wcsim", ("-lsimavr", "-lelf"))


def build_dir(sketch_dir: Path) -> Path:
    """The cache folder a sketch folder builds into (one per folder)."""
    key = hashlib.sha256(str(sketch_dir.resolve()).encode()).hexdigest()[:12]
    return cache_dir("firmware", f"{sketch_dir.name}-{key}")


def firmware_elf(sketch_dir: Path | None = None) -> Path:
    """Builds a sketch folder (default: the final_control firmware) with the firmware's
    Makefile, into the cache; a no-op when up to date; concurrent callers (processes
    too) wait for one another. Returns the ELF's path."""
    if shutil.which("avr-gcc") is None:
        raise BuildError(f"avr-gcc is missing: apt-get install {DEBIAN_PACKAGES}")
    sketch_dir = sketch_dir or firmware_dir()
    sketch = sketch_dir.name
    build = build_dir(sketch_dir)
    makefile = firmware_dir() / "Makefile"
    cmd = ["make", "-s", "-C", str(sketch_dir), "-f", str(makefile), f"SKETCH={sketch}",
           f"BUILD={build}", f"{build}/{sketch}.elf", f"{build}/{sketch}.hex"]
    # One build at a time per folder: test workers and threads that start together
    # must not run make over each other's half-written objects.
    with open(build / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        result = subprocess.run(cmd, capture_output=True, text=True)
        if result.returncode != 0:              # a damaged cache (a build cut short): once more, clean
            for item in build.iterdir():
                if item.name != ".lock":
                    shutil.rmtree(item) if item.is_dir() else item.unlink()
            result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise BuildError(f"building {sketch} failed:\n{' '.join(cmd)}\n{result.stdout}\n{result.stderr}")
    return build / f"{sketch}.elf"
