"""Claims in the docs that a command can show."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.simavr
def test_firmware_readme_sizes_match_avr_size(elf) -> None:
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    sizes = {m[0]: int(m[1]) for m in re.findall(r"^(\.\w+)\s+(\d+)", out, re.M)}
    flash = sizes[".text"] + sizes[".data"]
    ram = sizes[".data"] + sizes[".bss"]
    readme = (REPO / "firmware" / "final_control" / "README.md").read_text()
    assert f"| flash (program) | {flash} |" in readme, flash
    assert f"| RAM, static (.data + .bss) | {ram} |" in readme, ram
