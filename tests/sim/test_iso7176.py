"""``benchmarks/iso7176.py --quick`` runs on the port and prints well-formed tables: the
7176-3-style rows (a cell per column, figures that parse), the 7176-6-style lines and
the goals."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _rows(lines: list[str], header: str) -> tuple[list[str], list[list[str]]]:
    """The header cells and the rows of the Markdown table whose header starts so."""
    at = next(i for i, line in enumerate(lines) if line.startswith(header))
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines[at:] if line.startswith("|")]
    table = []
    for row in cells[2:]:
        if len(row) != len(cells[0]):
            break
        table.append(row)
    return cells[0], table


def test_the_quick_benchmark_prints_its_tables() -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "iso7176.py"), "--quick"],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    head, rows = _rows(lines, "| backend | grade | facing |")
    assert len(rows) == 4 and all(len(r) == len(head) for r in rows)
    assert [(r[1], r[2], r[3], r[4]) for r in rows] == [
        ("level", "level", "0.5", "command"), ("level", "level", "0.5", "last byte"),
        ("1:12", "down", "0.5", "command"), ("1:12", "down", "0.5", "last byte")]
    at_stop, distance, time_s, drift, top = (head.index(h) for h in (
        "at stop (m/s)", "distance (m)", "time (s)", "drift in 10 s (m)", "max after (m/s)"))
    for r in rows:
        assert 0.4 < float(r[at_stop]) < 0.6 and float(r[top]) > 0.0
        if r[distance] == "never":
            assert r[time_s] == "never" and r[drift].startswith("never at rest: ")
        else:
            assert float(r[distance]) > 0.0 and float(r[time_s]) > 0.0 and float(r[drift].split()[0]) >= 0.0
    assert rows[1][head.index("events")] == "WATCHDOG"          # the watchdog stopped it
    level = rows[0]
    assert level[distance] != "never" and float(level[drift]) < 0.05
    assert any(h.startswith("brake:") for h in head)          # with and without a brake
    _, tops = _rows(lines, "| backend | grade | top speed facing up")
    assert [t[1] for t in tops] == ["level", "1:12"]
    for t in tops:
        assert 0.0 < float(t[2]) and 2.0 < float(t[4]) < 3.0 and float(t[5]) > 1.0
    assert tops[0][2] == tops[0][4]                             # the level: one run
    assert sum(line.startswith("- ") for line in lines[lines.index("Goals:"):]) == 3
