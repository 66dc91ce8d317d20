"""MkDocs hook (mkdocs.yml): lays the site out as the checkout is, so relative links
between README.md, docs/, protocol/ and firmware/ resolve in the site too. The pages
of docs/ go to docs/, README.md becomes the home page, and the protocol and firmware
documents are added at their own paths."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

EXTRA = {"index.md": "README.md", "protocol/PROTOCOL.md": "protocol/PROTOCOL.md",
         "protocol/CAN.md": "protocol/CAN.md",
         "firmware/final_control/README.md": "firmware/final_control/README.md"}


def on_files(files: Files, config: Any) -> Files:
    root = Path(config.config_file_path).parent
    out = Files([])
    for f in files:
        if f.src_uri.endswith(".md"):
            out.append(File.generated(config, "docs/" + f.src_uri, abs_src_path=f.abs_src_path))
        else:
            out.append(f)
    for uri, rel in EXTRA.items():
        out.append(File.generated(config, uri, abs_src_path=str(root / rel)))
    return out
