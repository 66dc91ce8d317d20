"""Claims in the docs that a command can show."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.simavr
def test_firmware_readme_sizes_match_avr_size(elf) -> None:
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    sizes = {m[0]: int(m[1]) for m in re.findall(r"^(\.\w+)\s+(\d+)", out, re.M)}
    flash = sizes[".text"] + sizes[".data"]
    ram = sizes[".data"] + sizes[".bss"] + sizes.get(".noinit", 0)
    readme = (REPO / "firmware" / "final_control" / "README.md").read_text()
    assert f"| flash (program) | {flash} |" in readme, flash
    assert f"| RAM, static (.data + .bss + .noinit) | {ram} |" in readme, ram


def test_readme_navigation_example_runs() -> None:
    """The README's example for navigation code, run as written (on sim://)."""
    text = (REPO / "README.md").read_text()
    section = text[text.index("## For navigation code"):]
    code = section[section.index("```python") + len("```python"):]
    code = code[:code.index("```")]
    assert 'wcdrive.connect("sim://")' in code
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    chair = namespace["chair"]
    assert chair.odometry.pose.x > 0.3                      # 5 s at 0.5 m/s, ramped
    assert not chair.estop_latched


def test_bundled_protocol_documents_name_every_parameter() -> None:
    from wcdrive.firmware.params import PARAMS

    protocol = (REPO / "protocol" / "PROTOCOL.md").read_text()
    can_doc = (REPO / "protocol" / "CAN.md").read_text()
    for p in PARAMS:
        assert f"`{p.name}`" in protocol and f"`{p.name}`" in can_doc, p.name
