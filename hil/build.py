"""Builds what the harness needs from source: libwcsim.so and the firmware ELF.

Nothing prebuilt is shipped. ``harness_library()`` compiles ``hil/csrc/wcsim.c``
against Debian's libsimavr 1.6 into a cache directory keyed by the source's hash;
``firmware_elf()`` runs the firmware's Makefile. Both raise ``BuildError`` with the
command to install what is missing.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from wcdrive.native import BuildError, compile_shared

__all__ = ["BuildError", "firmware_elf", "harness_library"]

HIL_DIR = Path(__file__).resolve().parent
REPO_DIR = HIL_DIR.parent
HARNESS_SOURCE = HIL_DIR / "csrc" / "wcsim.c"
FIRMWARE_DIR = REPO_DIR / "firmware" / "final_control"
DEBIAN_PACKAGES = "gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev libelf-dev"


def harness_library() -> Path:
    """Path of libwcsim.so, compiled now if the source changed since the last build."""
    if not Path("/usr/include/simavr/sim_avr.h").exists():
        raise BuildError("libsimavr headers are missing: apt-get install libsimavr-dev libelf-dev")
    return compile_shared(HARNESS_SOURCE, "wcsim", ("-lsimavr", "-lelf"))


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
