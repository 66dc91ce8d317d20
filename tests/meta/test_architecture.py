"""The architecture holds: one-way layers, no cycles, no harness below the tools, one
source for the shared constants, a port twin for every function of the sketch, and a
library that works with the harness import blocked.

The layers (docs/architecture.md), lowest first; a module may import its own floor
and the floors below it, never above:

    python tests/meta/test_architecture.py [ROOT]    # print the floor graph of a checkout
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import textwrap
from collections import defaultdict
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

#: The floors, lowest first: (floor, name, the packages on it). Every floor is a
#: package of ``wcdrive/`` (the tools' floor has four: the CLI's ``tools``, the
#: scenario runner ``sim``, the navigation helpers ``navigation`` and the pytest plugin
#: ``testing``); the package root holds only ``ROOT_MODULES``. ``eddie`` is the second
#: robot, its modules each on the floor of the package they parallel (``EDDIE``).
PACKAGE_FLOORS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("utilities", ("_util", "errors")),
    ("avr", ("avr",)),
    ("protocol", ("protocol",)),
    ("firmware (port)", ("firmware",)),
    ("plant", ("plant",)),
    ("boards", ("boards",)),
    ("transports", ("transports",)),
    ("host", ("host",)),
    ("ros2", ("ros2",)),
    ("api", ("api", "__init__")),
    ("hil (harness)", ("hil",)),
    ("tools", ("sim", "navigation", "testing", "tools", "__main__")),
)
#: The package root: the public surface only.
ROOT_MODULES = {"__init__", "__main__", "api", "errors"}
#: The Eddie's modules, each on the floor of the package it parallels.
EDDIE = {"geometry": "protocol", "firmware": "firmware", "plant": "plant", "board": "boards",
         "serial_url": "transports", "robot": "host", "plugin": "api", "runner": "sim",
         "spin_arithmetic": "firmware", "position_controller": "firmware",
         "command_interpreter": "firmware"}


def _floors() -> tuple[tuple[int, str, tuple[str, ...]], ...]:
    out = []
    for number, (name, packages) in enumerate(PACKAGE_FLOORS):
        prefixes = tuple("wcdrive" if p == "__init__" else f"wcdrive.{p}" for p in packages)
        prefixes += tuple(f"wcdrive.eddie.{m}" for m, pkg in EDDIE.items() if pkg in packages)
        out.append((number, name, prefixes))
    return tuple(out)


#: (floor, name, module prefixes). A module belongs to the floor of its longest prefix.
FLOORS = _floors()
TOOLS_FLOOR = len(FLOORS) - 1


def test_the_package_root_holds_only_the_public_surface() -> None:
    """``ls wcdrive`` shows the floors: each entry is a floor's package or a root module."""
    packages = {p for _, packages in PACKAGE_FLOORS for p in packages} | {"eddie"}
    entries = {p.stem if p.suffix == ".py" else p.name
               for p in (REPO / "wcdrive").iterdir()
               if (p.suffix == ".py" or (p / "__init__.py").exists())}
    assert {e for e in entries if (REPO / "wcdrive" / f"{e}.py").exists()} == ROOT_MODULES
    assert entries - ROOT_MODULES <= packages, entries - ROOT_MODULES - packages
    assert packages - {"__init__", "__main__", "api", "errors", "hil"} <= entries


def test_importing_wcdrive_loads_no_simulator() -> None:
    """``import wcdrive`` gives the host side only: no pymunk, no board, no harness."""
    code = ("import sys, wcdrive\n"
            "print(sorted(m for m in sys.modules if m == 'pymunk' or m.startswith(("
            "'wcdrive.boards', 'wcdrive.plant', 'wcdrive.eddie.plant', 'wcdrive.hil', 'wcdrive.sim'))))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def modules(root: Path = REPO) -> dict[str, Path]:
    """Every module of the wheel by its import name (``hil/`` ships as ``wcdrive.hil``)."""
    found: dict[str, Path] = {}
    for top, name in (("wcdrive", "wcdrive"), ("hil", "wcdrive.hil")):
        base = root / top
        for path in sorted(base.rglob("*.py")):
            parts = path.relative_to(base).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join((name, *parts))] = path
    return found


def imports(path: Path, name: str, known: set[str]) -> set[str]:
    """The wcdrive modules ``path`` imports, lazily or not (and ``hil`` if it does)."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base
                       for alias in node.names]
        for target in targets:
            if target == "hil" or target.startswith("hil."):
                out.add(target)
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target.startswith("wcdrive") and target != name:
                out.add(target)
    return out


def graph(root: Path = REPO) -> dict[str, set[str]]:
    """Module -> the wcdrive modules it imports."""
    mods = modules(root)
    known = set(mods)
    return {name: imports(path, name, known) for name, path in mods.items()}


def floor(module: str) -> int:
    best, best_len = -1, -1
    for number, _, prefixes in FLOORS:
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = number, len(prefix)
    if best < 0:
        raise AssertionError(f"{module} is on no floor: add it to FLOORS and docs/architecture.md")
    return best


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in g.get(v, ()):
            if w not in g:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def upward(g: dict[str, set[str]]) -> list[tuple[str, str]]:
    return sorted((a, b) for a, deps in g.items() for b in deps
                  if not b.startswith("hil") and floor(b) > floor(a))


# ---- the tests ---------------------------------------------------------------------
def test_every_module_is_on_a_floor_and_no_import_goes_up() -> None:
    g = graph()
    assert len(g) > 50
    assert upward(g) == []


def test_no_import_cycles() -> None:
    assert cycles(graph()) == []


def test_nothing_imports_a_top_level_hil() -> None:
    offenders = {m: sorted(d for d in deps if d == "hil" or d.startswith("hil."))
                 for m, deps in graph().items()}
    assert {m: d for m, d in offenders.items() if d} == {}


def test_the_library_below_the_tools_never_imports_the_harness() -> None:
    g = graph()
    bad = sorted((m, d) for m, deps in g.items() for d in deps
                 if d.startswith("wcdrive.hil") and floor(m) < floor("wcdrive.hil"))
    assert bad == []


def test_the_checker_sees_an_upward_import(tmp_path: Path) -> None:
    """The checks can fail: a copy of the tree with one upward and one cyclic import."""
    for top in ("wcdrive", "hil"):
        subprocess.run(["cp", "-r", str(REPO / top), str(tmp_path / top)], check=True)
    f32 = tmp_path / "wcdrive" / "avr" / "f32.py"
    f32.write_text(f32.read_text() + "\n\ndef _bad() -> None:\n    from wcdrive.firmware import state\n")
    state = tmp_path / "wcdrive" / "firmware" / "state.py"
    state.write_text(state.read_text() + "\nfrom wcdrive.avr import f32 as _f32\n")
    codec = tmp_path / "wcdrive" / "protocol" / "codec.py"
    codec.write_text(codec.read_text() + "\nimport wcdrive.hil.traces\n")
    g = graph(tmp_path)
    assert ("wcdrive.avr.f32", "wcdrive.firmware.state") in upward(g)
    assert any("wcdrive.avr.f32" in c and "wcdrive.firmware.state" in c for c in cycles(g))
    assert ("wcdrive.protocol.codec", "wcdrive.hil.traces") in upward(g)


def test_ruff_bans_the_harness_below_the_tools() -> None:
    """ruff's TID251 (pyproject.toml) stops an import of wcdrive.hil in the library. The
    probe goes in on standard input under a library module's name: a file written into
    the package would show up in the tests that list it, run at the same time."""
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--stdin-filename",
                             str(REPO / "wcdrive" / "_tid251_probe.py"), "-"],
                            input="from wcdrive.hil.traces import Trace  # noqa: F401\n",
                            capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 1 and "TID251" in result.stdout, result.stdout


# ---- one source for the shared constants ---------------------------------------------
def _library_sources() -> dict[Path, str]:
    return {p: p.read_text() for p in (REPO / "wcdrive").rglob("*.py")}


def test_f_cpu_is_written_once() -> None:
    hits = [p for p, text in _library_sources().items()
            if re.search(r"^F_CPU\s*=", text, re.M) or re.search(r"\b16_?000_?000\b", text)]
    assert hits == [REPO / "wcdrive" / "avr" / "timer0.py"]


def test_geometry_and_parameter_table_come_from_the_spec() -> None:
    for path, text in _library_sources().items():
        code = "\n".join(line.split("#")[0] for line in text.splitlines())
        for literal in ("0.57", "0.1524", "17.59", "10000"):
            assert not re.search(rf"(?<![\d.]){re.escape(literal)}(?![\d])", code), (path, literal)
        assert '"kp_l"' not in code and "'kp_l'" not in code, path


def test_every_function_of_the_sketch_has_its_port_twin() -> None:
    """``parseBounded`` in final_control.ino is ``parse_bounded`` in wcdrive.firmware."""
    sketch = (REPO / "firmware" / "final_control" / "final_control.ino").read_text()
    names = re.findall(r"^(?:static |inline |extern \"C\" |__attribute__\(\(\w+\)\) )*"
                       r"[A-Za-z_][\w<>]*\s+\*?([A-Za-z_]\w*)\([^;{]*\)\s*\{", sketch, re.M | re.S)
    assert {"setup", "loop", "controlTick", "processByte", "parseBounded", "parseNumber"} <= set(names)
    port = set()
    for path in (REPO / "wcdrive" / "firmware").glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                port.add(node.name)
    #: What the sketch reads from hardware is an argument of the port.
    inputs = {"readEncoderL": "QuadratureDecoder.edge(state)",
              "readEncoderR": "QuadratureDecoder.edge(state)",
              "measureFreeRam": "Firmware.tick(free_ram=...)",
              "captureResetCause": "reset_cause_name(mcusr)"}

    def snake(name: str) -> str:
        return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower().replace("p_i_d", "pid")

    missing = sorted(n for n in names if n not in inputs and snake(n) not in port)
    assert missing == [], [snake(n) for n in missing]
    assert "edge" in port and "tick" in port


# ---- the library without the harness -----------------------------------------------
_BLOCK_HIL = textwrap.dedent("""
    import importlib.abc, sys
    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "wcdrive.hil" or name.startswith("wcdrive.hil."):
                raise ImportError(f"blocked: {name}")
            return None
    sys.meta_path.insert(0, Block())
""")


def _below_the_tools() -> list[str]:
    return sorted(m for m in modules() if floor(m) < floor("wcdrive.hil"))


def test_every_library_module_imports_with_the_harness_blocked() -> None:
    code = _BLOCK_HIL + textwrap.dedent(f"""
        import importlib
        for name in {_below_the_tools()!r}:
            importlib.import_module(name)
        assert not any(m.startswith("wcdrive.hil") for m in sys.modules)
        try:
            import wcdrive.hil
        except ImportError:
            print("blocked ok")
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert result.returncode == 0, result.stderr
    assert "blocked ok" in result.stdout


@pytest.mark.simavr
def test_simavr_drives_the_chair_with_the_harness_blocked(elf: Path) -> None:
    code = _BLOCK_HIL + textwrap.dedent(f"""
        import time, wcdrive
        with wcdrive.connect("simavr://{elf}?realtime=0") as chair:
            start = chair.wait_for_telemetry()
            end = time.monotonic() + 2.0
            while time.monotonic() < end:
                chair.set_wheels(3.0, 3.0)
                time.sleep(0.1)
            last = chair.wait_for_telemetry()
            assert chair.protocol_version == 4, chair.protocol_version
            assert last.count_right - start.count_right > 100, (start, last)
            assert last.vel_right > 0.5, last
        assert not any(m.startswith("wcdrive.hil") for m in sys.modules)
        print("drove", last.count_right - start.count_right)
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/",
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert "drove" in result.stdout


def _report(root: Path) -> None:
    g = graph(root)
    edges: dict[tuple[str, str], int] = defaultdict(int)
    for a, deps in g.items():
        for b in deps:
            if not b.startswith("hil"):
                edges[(FLOORS[floor(a)][1], FLOORS[floor(b)][1])] += 1
    print(f"{len(g)} modules, {sum(len(d) for d in g.values())} imports")
    for (a, b), n in sorted(edges.items(), key=lambda e: (floor_of_name(e[0][0]), floor_of_name(e[0][1]))):
        print(f"  {a:32s} -> {b:32s} {n:3d}")
    print("upward:", upward(g) or "none")
    print("cycles:", cycles(g) or "none")


#: The longest a module may be: small modules, one concern each (docs/architecture.md).
MODULE_LINES_MAX = 599


def test_every_module_is_under_600_lines() -> None:
    long = {name: n for name, path in modules().items()
            if (n := len(path.read_text().splitlines())) > MODULE_LINES_MAX}
    assert not long, long


def floor_of_name(label: str) -> int:
    return next(n for n, name, _ in FLOORS if name == label)


if __name__ == "__main__":
    _report(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO)
