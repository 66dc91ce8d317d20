"""The protocol's machine-readable spec (``protocol/spec.toml``): every constant that the
firmware and the Python side share, the parameter table, and the firmware header
generated from them. Every shared constant in Python comes from here.

    python -m wcdrive.protocol.spec            # print the header
    python -m wcdrive.protocol.spec --write    # write firmware/final_control/wc_config.h
    python -m wcdrive.protocol.spec --check    # exit 1 when the header is out of date
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wcdrive._util.resources import firmware_dir, protocol_dir

__all__ = ["PARAMETERS", "Parameter", "build_id", "constants", "header", "load", "value"]


def spec_path() -> Path:
    """``protocol/spec.toml``."""
    return protocol_dir() / "spec.toml"


def header_path() -> Path:
    """``firmware/final_control/wc_config.h``, generated from the spec."""
    return firmware_dir() / "wc_config.h"


@functools.cache
def load(path: Path | None = None) -> dict[str, Any]:
    """The spec as parsed TOML (cached)."""
    return tomllib.loads((path or spec_path()).read_text())


def _sections(spec: dict[str, Any]) -> list[dict[str, Any]]:
    return [s for s in spec.values() if isinstance(s, dict)]


def constants(spec: dict[str, Any] | None = None) -> dict[str, int | float | str]:
    """Every constant by name (without the WC_ prefix): ints for ``int``/``ulong``,
    Python floats for ``float`` (the port rounds them to binary32 itself), str for ``str``."""
    spec = spec or load()
    out: dict[str, int | float | str] = {}
    for section in _sections(spec):
        for name, entry in section.items():
            if isinstance(entry, dict):
                kind = entry["type"]
                out[name] = (float(entry["value"]) if kind == "float" else str(entry["value"])
                             if kind == "str" else int(entry["value"]))
    return out


def value(name: str) -> int | float | str:
    """One constant of the spec by name."""
    return constants()[name]


def text(name: str) -> str:
    """A string constant of the spec by name."""
    v = value(name)
    if not isinstance(v, str):
        raise TypeError(f"{name} is not a string in spec.toml")
    return v


def integer(name: str) -> int:
    """An integer constant of the spec by name."""
    v = value(name)
    if not isinstance(v, int):
        raise TypeError(f"{name} is a float in spec.toml")
    return v


def real(name: str) -> float:
    """A numeric constant of the spec by name, as a float."""
    v = value(name)
    if isinstance(v, str):
        raise TypeError(f"{name} is a string in spec.toml")
    return float(v)


@dataclass(frozen=True)
class Parameter:
    """A runtime parameter (``get:<name>`` / ``set:<name>=<value>``)."""

    name: str          # as on the wire
    field: str         # the firmware global (FirmwareState field) that holds it
    low: float         # range, as the spec writes it (binary32 rounding is the port's)
    high: float
    integer: bool = False
    #: Its WC_PARAM index on CAN, where that is not its place in the table (None).
    can_index: int | None = None


def _bound(entry: float | str) -> float:
    return real(entry) if isinstance(entry, str) else float(entry)


def parameters(spec: dict[str, Any] | None = None) -> tuple[Parameter, ...]:
    """The parameter table in the firmware's order."""
    spec = spec or load()
    return tuple(Parameter(p["name"], p["field"], _bound(p["low"]), _bound(p["high"]),
                           bool(p.get("integer", False)), p.get("can_index")) for p in spec["parameter"])


PARAMETERS: tuple[Parameter, ...] = parameters()

#: The drive limits a profile holds, in the parameter table's order (contiguous there).
PROFILE_PARAMETERS: tuple[str, ...] = ("fwd_speed", "rev_speed", "drive_accel", "drive_decel",
                                       "turn_speed", "turn_accel", "turn_at_speed", "tremor_damping")


@dataclass(frozen=True)
class Profile:
    """A drive profile's preset (``[[profile]]``): its name and its drive limits, in
    ``PROFILE_PARAMETERS`` order, as the spec writes them."""

    name: str
    values: tuple[float, ...]


def profiles(spec: dict[str, Any] | None = None) -> tuple[Profile, ...]:
    """The drive profiles' presets, by number."""
    spec = spec or load()
    return tuple(Profile(p["name"], tuple(_bound(p[name]) for name in PROFILE_PARAMETERS))
                 for p in spec["profile"])


PROFILES: tuple[Profile, ...] = profiles()


def build_id(sketch_dir: Path | None = None) -> str:
    """The firmware's build id, as its Makefile computes it: the first 8 hex digits of
    the SHA-256 of the sketch (``<sketch>.ino``) followed by its headers (``*.h``,
    sorted by name). ``HELLO:`` carries it, so a host can tell which sources a board
    runs."""
    folder = sketch_dir or firmware_dir()
    data = (folder / f"{folder.name}.ino").read_bytes()
    for header_file in sorted(folder.glob("*.h"), key=lambda p: p.name):
        data += header_file.read_bytes()
    return hashlib.sha256(data).hexdigest()[:8]


def _literal(entry: dict[str, Any]) -> str:
    value, kind = entry["value"], entry["type"]
    if kind == "float":
        return f"{float(value)!r}f"
    if kind == "ulong":
        return f"{int(value)}UL"
    if kind == "str":
        return '"' + str(value) + '"'
    return str(int(value))


def header(spec: dict[str, Any] | None = None) -> str:
    """The text of ``wc_config.h``."""
    spec = spec or load()
    lines = [
        "// wc_config.h: every constant of the final_control firmware in one place.",
        "//",
        "// GENERATED from protocol/spec.toml by `python -m wcdrive.protocol.spec --write`:",
        "// edit the spec, not this file. tests/protocol/test_protocol.py fails when they differ.",
        "#ifndef WC_CONFIG_H",
        "#define WC_CONFIG_H",
    ]
    for section in _sections(spec):
        lines += ["", f"// ---- {section['title']} " + "-" * max(3, 70 - len(section["title"]))]
        for name, entry in section.items():
            if not isinstance(entry, dict):
                continue
            define = f"#define WC_{name} {_literal(entry)}"
            lines.append(f"{define:<34} // {entry['doc']}" if entry.get("doc") else define)
    lines += ["", "// ---- The drive profiles' presets ([[profile]]), rows of "
              + ", ".join(PROFILE_PARAMETERS) + " " + "-" * 3,
              "#define WC_PROFILE_PRESETS { \\"]
    for number, profile in enumerate(profiles(spec)):
        row = ", ".join(f"{v!r}f" for v in profile.values)
        lines.append(f"  {{ {row} }},  /* {number}: {profile.name} */ \\")
    lines += ["}", "", "#endif", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m wcdrive.protocol.spec [--write | --check]``."""
    parser = argparse.ArgumentParser(prog="python -m wcdrive.protocol.spec")
    parser.add_argument("--write", action="store_true")
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args(argv)
    text = header()
    if args.write:
        header_path().write_text(text)
    elif args.check:
        if header_path().read_text() != text:
            print(f"{header_path()} is out of date: run python -m wcdrive.protocol.spec --write")
            return 1
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
