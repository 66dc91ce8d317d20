"""Every reference the prose makes resolves: each repository path and each dotted
``wcdrive.`` name named by the docs (README.md, docs/, protocol/, the sketch's README),
by the docstrings and comments of the Python sources, by the comments of the C sources
and the sketch, by the comments of the shell scripts, and by pyproject.toml and
mkdocs.yml. A path must exist (a glob must match a file; a ``path::test`` node id names a
test that is in the file); a name must import and getattr to something (or be a logger,
an entry-point group, a data package or a C helper that the code declares). And every
page of docs/ is in the site's nav.

What is exempt is listed below, each with its reason, and each exemption must still be
needed."""

from __future__ import annotations

import ast
import importlib
import inspect
import io
import re
import tokenize
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]

#: Top-level entries of the checkout that are outputs or caches, not sources (.gitignore):
#: a token starting with one of them is not taken for a reference into the repository.
OUTPUTS = {".git", "build", "wcdrive.egg-info", "wcdrive-out", "out", ".hypothesis", ".mypy_cache",
           ".pytest_cache", ".ruff_cache", ".benchmarks", "__pycache__", ".venv"}

#: (file, path) pairs where a path into the checkout legitimately does not exist, with
#: why; file "*": in any file.
PATH_EXEMPT: dict[tuple[str, str], str] = {}

#: (file, name) pairs where a ``wcdrive.`` name legitimately does not resolve, with why;
#: file "*": in any file.
NAME_EXEMPT: dict[tuple[str, str], str] = {
    ("*", "wcdrive.dbc"): "the CAN database's file name (protocol/wcdrive.dbc), not a Python name",
}

#: Pages of docs/ that are deliberately not in mkdocs.yml's nav, with why.
NAV_EXEMPT: dict[str, str] = {}

#: The markdown documents whose whole text is read.
DOCS = ["README.md", "docs/*.md", "protocol/*.md", "firmware/final_control/README.md"]
#: The Python sources whose docstrings and comments are read.
PYTHON = ["wcdrive/**/*.py", "hil/**/*.py", "tests/**/*.py", "benchmarks/**/*.py", "scripts/**/*.py",
          "examples/*.py", "setup.py", "_wcdrive_serial_urls.py"]
#: The C and C++ sources whose comments are read.
C_SOURCES = ["wcdrive/**/csrc/*.c", "wcdrive/**/csrc/*.h", "firmware/**/*.ino", "firmware/**/*.h"]
#: The shell scripts whose comments are read.
SHELL = ["scripts/*.sh", ".ci/run"]
#: The configuration files whose whole text is read.
CONFIG = ["pyproject.toml", "mkdocs.yml"]


@dataclass(frozen=True)
class Ref:
    """One reference: ``kind`` is "path" or "name"; ``where`` is ``file:line``."""

    kind: str
    text: str
    where: str


def _file(ref: Ref) -> str:
    return ref.where.rsplit(":", 1)[0]


def _files(patterns: list[str]) -> list[Path]:
    found = {p for pattern in patterns for p in REPO.glob(pattern) if p.is_file()}
    return sorted(p for p in found if "__pycache__" not in p.parts
                  and not (set(p.relative_to(REPO).parts[:1]) & OUTPUTS))


def python_prose(source: str) -> Iterator[tuple[int, str]]:
    """(line, text) of each docstring (any bare string statement) and comment of a
    Python source."""
    def statements(body: list[ast.stmt]) -> Iterator[ast.stmt]:
        for node in body:
            yield node
            for field in ("body", "orelse", "finalbody", "handlers", "cases"):
                yield from statements(getattr(node, field, []))

    for node in statements(ast.parse(source).body):
        if (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
                and isinstance(node.value.value, str)):
            yield node.lineno, node.value.value
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string


def c_comments(source: str) -> Iterator[tuple[int, str]]:
    """(line, text) of each ``//`` and ``/* */`` comment of a C source; string and
    character literals are skipped."""
    i, n = 0, len(source)
    while i < n:
        c = source[i]
        if c in "\"'":
            j = i + 1
            while j < n and source[j] != c and source[j] != "\n":
                j += 2 if source[j] == "\\" else 1
            i = j + 1
        elif source.startswith("//", i):
            j = source.find("\n", i)
            j = n if j < 0 else j
            yield source.count("\n", 0, i) + 1, source[i:j]
            i = j
        elif source.startswith("/*", i):
            j = source.find("*/", i + 2)
            j = n if j < 0 else j + 2
            yield source.count("\n", 0, i) + 1, source[i:j]
            i = j
        else:
            i += 1


def shell_comments(source: str) -> Iterator[tuple[int, str]]:
    """(line, text) of each comment line of a shell script."""
    for number, line in enumerate(source.splitlines(), 1):
        if line.lstrip().startswith("#"):
            yield number, line


def prose() -> Iterator[tuple[str, int, str]]:
    """(file, first line, text) of every piece of prose the check reads."""
    for path in _files(DOCS) + _files(CONFIG):
        yield str(path.relative_to(REPO)), 1, path.read_text()
    for patterns, extract in ((PYTHON, python_prose), (C_SOURCES, c_comments), (SHELL, shell_comments)):
        for path in _files(patterns):
            for line, text in extract(path.read_text()):
                yield str(path.relative_to(REPO)), line, text


@cache
def _roots() -> tuple[list[str], list[str]]:
    entries = [p for p in REPO.iterdir() if p.name not in OUTPUTS]
    return (sorted(p.name for p in entries if p.is_dir()), sorted(p.name for p in entries if p.is_file()))


@cache
def _patterns() -> tuple[re.Pattern[str], re.Pattern[str]]:
    dirs, files = _roots()
    alternatives = "|".join([*(re.escape(d) + r"/[\w.*?/-]*" for d in dirs), *map(re.escape, files)])
    path = re.compile(rf"(?<![\w./~$@-])(?:{alternatives})(?:::\w+)*(?![\w-])")
    name = re.compile(r"(?<![\w./-])wcdrive(?:\.\w+)+(?::\w+(?:\.\w+)*)?")
    return path, name


def references(text: str, file: str = "<text>", line: int = 1) -> list[Ref]:
    """The repository paths and ``wcdrive.`` names in ``text`` (which starts at ``line``
    of ``file``)."""
    path, name = _patterns()
    out = []
    for kind, pattern in (("path", path), ("name", name)):
        for m in pattern.finditer(text):
            token = m[0].rstrip(".")
            if token:
                out.append(Ref(kind, token, f"{file}:{line + text.count(chr(10), 0, m.start())}"))
    return out


@cache
def all_references() -> tuple[Ref, ...]:
    """Every reference in every piece of prose the check reads."""
    return tuple(ref for file, line, text in prose() for ref in references(text, file, line))


@cache
def path_problem(token: str) -> str | None:
    """Why ``token`` (a repository path, a glob or a ``path::test`` node id) does not
    resolve, or None."""
    path, *node = token.split("::")
    if any(c in path for c in "*?"):
        return None if any(REPO.glob(path)) else "matches no file"
    if not (REPO / path).exists():
        return "no such file or directory"
    if node:
        if not (REPO / path).is_file():
            return "a node id on a directory"
        source = (REPO / path).read_text()
        if not re.search(rf"^\s*(?:async\s+)?(?:def|class)\s+{re.escape(node[0])}\b", source, re.M):
            return f"{path} has no {node[0]}"
    return None


@cache
def _declared_names() -> frozenset[str]:
    """``wcdrive.``-dotted names that are not (or not always) Python objects of a
    checkout: the logger names the library creates, the entry-point groups pyproject.toml
    declares, the packages of data setup.py makes (``DATA``: in a built wheel only) and
    the C helpers it builds (``NATIVE``: only where a compiler was)."""
    loggers = {m[1] for path in _files(["wcdrive/**/*.py"])
               for m in re.finditer(r"getLogger\(\"([\w.]+)\"\)", path.read_text())}
    pyproject = (REPO / "pyproject.toml").read_text()
    groups = set(re.findall(r"^\[project\.entry-points\.\"([\w.]+)\"\]", pyproject, re.M))
    setup = (REPO / "setup.py").read_text()
    data = set(re.findall(r"^\s+\"(wcdrive\._data\.[\w.]+)\":", setup, re.M))
    packages = {".".join(name.split(".")[:n]) for name in data for n in range(2, name.count(".") + 2)}
    helpers = set(re.findall(r"Extension\(\"(wcdrive\.[\w.]+)\"", setup))
    return frozenset(loggers | groups | packages | helpers)


def _instance_attribute(cls: type, attr: str) -> bool:
    """Whether instances of ``cls`` have ``attr`` (annotated, a dataclass field, a slot, or
    assigned as ``self.attr`` in a method)."""
    for klass in cls.__mro__:
        if attr in getattr(klass, "__annotations__", {}) or attr in getattr(klass, "__slots__", ()):
            return True
        try:
            source = inspect.getsource(klass)
        except (OSError, TypeError):
            continue
        if re.search(rf"\bself\.{re.escape(attr)}\s*(?::[^=\n]+)?=", source):
            return True
    return False


@cache
def _quietly_import(module: str) -> object:
    """The module; the old names kept for a release warn when imported, by design."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return importlib.import_module(module)


def name_problem(token: str) -> str | None:
    """Why ``token`` (a dotted ``wcdrive.`` name, perhaps ``module:attribute``) does not
    resolve, or None: the longest importable module prefix is imported, the rest is
    looked up with getattr (or, on a class, as an instance attribute)."""
    if token in _declared_names():
        return None
    parts = token.replace(":", ".").split(".")
    obj: object = _quietly_import(parts[0])
    for i, part in enumerate(parts[1:], 1):
        if inspect.ismodule(obj):
            module = ".".join(parts[:i + 1])
            try:
                obj = _quietly_import(module)
                continue
            except ImportError as exc:
                if not (isinstance(exc, ModuleNotFoundError) and exc.name == module):
                    return f"importing {module}: {exc}"
        if hasattr(obj, part):
            obj = getattr(obj, part)
        elif isinstance(obj, type) and _instance_attribute(obj, part) and i == len(parts) - 1:
            return None
        else:
            return f"{'.'.join(parts[:i])} has no {part}"
    return None


def problems(refs: list[Ref]) -> list[str]:
    """``where: token (why)`` of each reference that does not resolve and is not exempt."""
    out = []
    for ref in refs:
        keys = {(_file(ref), ref.text), ("*", ref.text)}
        if ref.kind == "path" and not keys & PATH_EXEMPT.keys():
            why = path_problem(ref.text)
        elif ref.kind == "name" and not keys & NAME_EXEMPT.keys():
            why = name_problem(ref.text)
        else:
            continue
        if why:
            out.append(f"{ref.where}: {ref.text} ({why})")
    return out


def nav_pages(mkdocs_yml: str) -> set[str]:
    """The pages of a mkdocs.yml's nav."""
    def walk(node: object) -> Iterator[str]:
        if isinstance(node, str):
            yield node
        elif isinstance(node, list):
            for item in node:
                yield from walk(item)
        elif isinstance(node, dict):
            for value in node.values():
                yield from walk(value)

    return set(walk(yaml.safe_load(mkdocs_yml)["nav"]))


def pages_not_in_nav(mkdocs_yml: str, pages: list[str]) -> list[str]:
    """The pages of ``pages`` that are neither in the nav nor exempt."""
    nav = nav_pages(mkdocs_yml)
    return [page for page in pages if page not in nav and page not in NAV_EXEMPT]


# -- the checks -------------------------------------------------------------------------

def test_every_repository_path_exists() -> None:
    bad = problems([ref for ref in all_references() if ref.kind == "path"])
    assert not bad, "stale paths:\n" + "\n".join(bad)


def test_every_wcdrive_name_resolves() -> None:
    bad = problems([ref for ref in all_references() if ref.kind == "name"])
    assert not bad, "stale names:\n" + "\n".join(bad)


def test_every_docs_page_is_in_the_nav() -> None:
    pages = [str(p.relative_to(REPO)) for p in sorted((REPO / "docs").glob("*.md"))]
    assert pages_not_in_nav((REPO / "mkdocs.yml").read_text(), pages) == []
    missing = {page for page in nav_pages((REPO / "mkdocs.yml").read_text())
               if page != "index.md" and not (REPO / page).is_file()}
    assert not missing, missing


def test_every_exemption_is_still_needed() -> None:
    named = {key for ref in all_references() for key in ((_file(ref), ref.text), ("*", ref.text))}
    for key in [*PATH_EXEMPT, *NAME_EXEMPT]:
        assert key in named, f"{key} is exempt but no longer there: drop it"
    for _, token in PATH_EXEMPT:
        assert path_problem(token), f"{token} is exempt but resolves: drop it"
    for _, token in NAME_EXEMPT:
        assert name_problem(token), f"{token} is exempt but resolves: drop it"
    nav = nav_pages((REPO / "mkdocs.yml").read_text())
    for page in NAV_EXEMPT:
        assert (REPO / page).is_file() and page not in nav, page


# -- the check checks -------------------------------------------------------------------

def test_the_check_reads_every_kind_of_source() -> None:
    """Not trivially green: it finds hundreds of references, in each kind of source."""
    refs = all_references()
    paths = {ref.text for ref in refs if ref.kind == "path"}
    names = {ref.text for ref in refs if ref.kind == "name"}
    # 736 paths (218 different) and 530 names (228 different) when this was written
    assert len([r for r in refs if r.kind == "path"]) >= 600 and len(paths) >= 180, len(paths)
    assert len([r for r in refs if r.kind == "name"]) >= 400 and len(names) >= 180, len(names)
    files = {_file(ref) for ref in refs}
    for expected in ("README.md", "docs/architecture.md", "protocol/PROTOCOL.md",
                     "firmware/final_control/README.md", "pyproject.toml", "mkdocs.yml",
                     "wcdrive/firmware/csrc/tick_fast.c", "firmware/final_control/final_control.ino",
                     "wcdrive/api.py", "tests/meta/test_docs_site.py", "scripts/test.sh"):
        assert expected in files, expected


def test_the_check_catches_a_stale_reference() -> None:
    gone = "test_" + "gone_away"
    text = (f"See tests/meta/{gone}.py, tests/meta/test_references.py::{gone}, tests/zz_*.py,\n"
            f"wcdrive.api.{gone} and wcdrive.{gone}.thing; but tests/meta/test_references.py,\n"
            "tests/meta/test_*.py, tests/meta/test_references.py::test_the_check_catches_a_stale_reference,\n"
            "wcdrive.api.Wheelchair, wcdrive.connect and wcdrive.tools.cli:main are fine,\n"
            "as are /tmp/tests/x.py, wcdrive-out/x.png and build/lib/wcdrive/x.py.")
    refs = references(text, "fake.md")
    assert {r.text for r in refs} >= {"tests/meta/test_references.py", "wcdrive.connect"}
    bad = problems(refs)
    assert [b.split(": ")[1].split(" (")[0] for b in bad] == [
        f"tests/meta/{gone}.py", f"tests/meta/test_references.py::{gone}", "tests/zz_*.py",
        f"wcdrive.api.{gone}", f"wcdrive.{gone}.thing"], bad
    assert bad[0].startswith("fake.md:1: ") and bad[3].startswith("fake.md:2: ")


def test_the_check_reads_comments_and_docstrings_only() -> None:
    gone = "wcdrive." + "gone_away"
    python = (f'"""Module {gone}."""\nx = "{gone}.code"  # {gone}.comment\n\n\n'
              f'def f():\n    """{gone}.doc"""\n')
    assert sorted(text for _, text in python_prose(python)) == sorted(
        [f"Module {gone}.", f"# {gone}.comment", f"{gone}.doc"])
    c = f'/* {gone}.block\n */\nconst char *s = "// {gone}.string"; // {gone}.line\nchar q = \'"\';\n'
    assert [(line, text) for line, text in c_comments(c)] == [
        (1, f"/* {gone}.block\n */"), (3, f"// {gone}.line")]


def test_the_check_catches_the_stale_references_it_was_written_for() -> None:
    """The tick's C source named its test where it was before tests/ had folders, and a
    module that became wcdrive._util.native; pyproject.toml and mkdocs.yml named tests
    that moved too."""
    old = ("/*\n * " + "tests/test_tick_fast.py holds this to the Python tick.\n * Built by "
           + "wcdrive.native (gcc -O2 -ffp-contract=off).\n */\nstatic int x = 1;  // fine\n")
    refs = [ref for line, text in c_comments(old) for ref in references(text, "tick_fast.c", line)]
    assert problems(refs) == [
        "tick_fast.c:2: tests/test_tick_fast.py (no such file or directory)",
        "tick_fast.c:3: wcdrive.native (wcdrive has no native)"]
    toml = "# the layering: " + "tests/test_architecture.py checks every floor\n"
    assert problems(references(toml, "pyproject.toml")) == [
        "pyproject.toml:1: tests/test_architecture.py (no such file or directory)"]


def test_the_nav_check_sees_a_missing_page() -> None:
    yml = "nav:\n  - Home: index.md\n  - A: docs/a.md\n  - More:\n    - B: docs/b.md\n"
    assert pages_not_in_nav(yml, ["docs/a.md", "docs/b.md", "docs/c.md"]) == ["docs/c.md"]
