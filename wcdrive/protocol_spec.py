"""The protocol's machine-readable spec (``protocol/spec.toml``) and the firmware
header generated from it.

    python -m wcdrive.protocol_spec            # print the header
    python -m wcdrive.protocol_spec --write    # write firmware/final_control/wc_config.h
    python -m wcdrive.protocol_spec --check    # exit 1 when the header is out of date
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SPEC = REPO / "protocol" / "spec.toml"
HEADER = REPO / "firmware" / "final_control" / "wc_config.h"


def load(path: Path = SPEC) -> dict:
    return tomllib.loads(path.read_text())


def constants(spec: dict | None = None) -> dict[str, int | float]:
    """Every constant by name (without the WC_ prefix)."""
    spec = spec or load()
    out: dict[str, int | float] = {}
    for section in spec.values():
        if isinstance(section, dict):
            for name, entry in section.items():
                if isinstance(entry, dict):
                    out[name] = entry["value"]
    return out


def _literal(entry: dict) -> str:
    value, kind = entry["value"], entry["type"]
    if kind == "float":
        return f"{float(value)!r}f"
    if kind == "ulong":
        return f"{int(value)}UL"
    return str(int(value))


def header(spec: dict | None = None) -> str:
    spec = spec or load()
    lines = [
        "// wc_config.h: every constant of the final_control firmware in one place.",
        "//",
        "// GENERATED from protocol/spec.toml by `python -m wcdrive.protocol_spec --write`:",
        "// edit the spec, not this file. tests/test_protocol.py fails when they differ.",
        "#ifndef WC_CONFIG_H",
        "#define WC_CONFIG_H",
    ]
    for section in spec.values():
        if not isinstance(section, dict):
            continue
        lines += ["", f"// ---- {section['title']} " + "-" * max(3, 70 - len(section["title"]))]
        for name, entry in section.items():
            if not isinstance(entry, dict):
                continue
            define = f"#define WC_{name} {_literal(entry)}"
            lines.append(f"{define:<34} // {entry['doc']}" if entry.get("doc") else define)
    lines += ["", "#endif", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wcdrive.protocol_spec")
    parser.add_argument("--write", action="store_true")
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args(argv)
    text = header()
    if args.write:
        HEADER.write_text(text)
    elif args.check:
        if HEADER.read_text() != text:
            print(f"{HEADER} is out of date: run python -m wcdrive.protocol_spec --write")
            return 1
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
