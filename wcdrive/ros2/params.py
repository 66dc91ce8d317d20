"""ROS 2 parameter files and ``-p`` values as ROS 2 Jazzy reads them (rcl 9.2's
``rcl_yaml_param_parser``, rclpy's matching of node names). Pure: ``parse_file`` reads
the one file it is given, nothing else does I/O.

The file (``parse_file_events`` in ``rcl_yaml_param_parser/src/parse.c``, ported event
for event over libyaml's events, which PyYAML gives): mapping keys are node names, joined
with '/' level by level (``/ns:`` then ``node:`` is ``/ns/node``), until the key
``ros__parameters``; its mapping holds the parameters, nested keys joined with '.'
(``linear:`` ``x:`` ``max_velocity:`` is ``linear.x.max_velocity``); a value is a
scalar or a flat sequence of scalars of one type. Node names may be ``/**`` (any
node) and ``/*`` (one name) as whole components, validated as rmw validates names.
Aliases, sequences of maps and a value before ``ros__parameters`` are refused.

A scalar's type (``get_value`` in ``parse.c``): tagged ``!!str`` or quoted: a string;
``true``/``yes``/``on``/``y`` and ``false``/``no``/``off``/``n`` (three casings each): a
bool; what C's ``strtoll(s, 0)`` reads whole (so ``0x1f`` and the octal ``010``): an
integer; ``.nan``/``.inf``/``-.inf`` and what ``strtod`` reads whole (``1.0``, ``1e3``,
``nan``, ``0x1p3``; not ``1e999``, out of range): a double; anything else a string. So
``1`` is an integer and ``1.0`` a double, as rclcpp's typed parameters see them.

Files and ``-p`` rules go into one ``ParameterStore``, in order: a node name or a
parameter seen again is the same entry, overwritten in place. As in rcl, a value of
another type does not clear the old one: the value is the first of bool, integer,
double, string, then the arrays (``rcl_variant_t`` as rclcpp and rclpy read it).

``ParameterStore.for_node(fqn)``: the parameters that node gets (rclpy's
``_populate_node_parameters_from_rcl_params``): each node name gets a leading '/',
``/*`` becomes ``(/\\w+)`` and ``/**`` ``(/\\w+)*``, and the name must match the whole
fully qualified node name; matching entries are applied in the store's order.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from wcdrive.errors import WcdriveFileError
from wcdrive.ros2.names import (
    COLON,
    DOT,
    FORWARD_SLASH,
    SEPARATOR,
    TOKEN,
    WILD_MULTI,
    WILD_ONE,
    Lookahead,
    RosNameError,
    validate_namespace,
    validate_node_name,
)

__all__ = ["PARAMS_KEY", "TYPES", "ParameterError", "ParameterStore", "Value", "parse_param_rule",
           "scalar_value"]

#: The key that opens a node's parameters.
PARAMS_KEY = "ros__parameters"
#: The parameter types a YAML value can have, in the order a variant is read.
TYPES = ("bool", "integer", "double", "string", "bool_array", "integer_array", "double_array",
         "string_array")
_STR_TAG = "tag:yaml.org,2002:str"
_TRUE = {"Y", "y", "yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"}
_FALSE = {"N", "n", "no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"}
_SPECIAL_FLOATS = {".nan", ".NaN", ".NAN", ".inf", ".Inf", ".INF", "+.inf", "+.Inf", "+.INF",
                   "-.inf", "-.Inf", "-.INF"}
_SPACE = " \t\n\v\f\r"
_STRTOLL = re.compile(rf"[{_SPACE}]*([+-]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)")
_DECIMAL = re.compile(rf"[{_SPACE}]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_HEXFLOAT = re.compile(rf"[{_SPACE}]*[+-]?0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)"
                       r"(?:[pP][+-]?[0-9]+)?")
_INFNAN = re.compile(rf"[{_SPACE}]*[+-]?(?:inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?)", re.I)


class ParameterError(WcdriveFileError):
    """A parameter file or ``-p`` rule that rcl would refuse, or a value a node cannot
    take (the message says where and why)."""


@dataclass(frozen=True)
class Value:
    """A parameter's value: ``type`` one of ``TYPES`` or "not set", and the Python value
    (a list for the arrays)."""

    type: str
    value: Any

    def yaml(self) -> str:
        """The value as YAML text that reads back as the same type and value."""
        return _yaml(self.type, self.value)


def _yaml(kind: str, value: Any) -> str:
    if kind.endswith("_array"):
        return "[" + ", ".join(_yaml(kind[:-6], v) for v in value) + "]"
    if kind == "bool":
        return "true" if value else "false"
    if kind == "integer":
        return str(value)
    if kind == "double":
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        return repr(float(value))
    if kind == "string":
        return "'" + str(value).replace("'", "''") + "'"
    return "[]"


# ---- scalars ---------------------------------------------------------------------------------
def scalar_value(text: str, style: str | None = None, tag: str | None = None) -> tuple[str, Any]:
    """(type, value) of a YAML scalar ``text`` written in ``style`` (None: plain, "'" or
    '"' quoted, "|" or ">" block) with ``tag`` (module docstring; rcl's ``get_value``)."""
    if tag == _STR_TAG:
        return "string", text
    if style not in ("'", '"'):
        if text in _TRUE:
            return "bool", True
        if text in _FALSE:
            return "bool", False
        integer = _strtoll(text)
        if integer is not None:
            return "integer", integer
        if text in _SPECIAL_FLOATS:
            value = float("nan") if "nan" in text.lower() else float("inf")
            return "double", -value if text.startswith("-") else value
        double = _strtod(text)
        if double is not None:
            return "double", double
    return "string", text


def _strtoll(text: str) -> int | None:
    """C's ``strtoll(text, &end, 0)`` when it reads all of ``text`` in range, else None."""
    m = _STRTOLL.fullmatch(text)
    if not m:
        return None
    digits = m[2]
    if digits[:2] in ("0x", "0X"):
        value = int(digits[2:], 16)
    elif len(digits) > 1 and digits[0] == "0":
        value = int(digits, 8)
    else:
        value = int(digits)
    value = -value if m[1] == "-" else value
    return value if -2**63 <= value < 2**63 else None         # ERANGE: not an integer


def _strtod(text: str) -> float | None:
    """glibc's ``strtod(text, &end)`` when it reads all of ``text`` without ERANGE, else
    None: ERANGE on overflow, and on underflow (a result below the smallest normal
    double that is not exactly the text's value: ``1e-310``, not ``0x1p-1074``)."""
    body = text.lstrip(_SPACE)
    sign = -1 if body.startswith("-") else 1
    if _DECIMAL.fullmatch(text):
        value = float(body)
        zero = not re.search(r"[1-9]", re.sub(r"[eE].*", "", body))

        def exact() -> Fraction:
            return Fraction(body)
    elif _HEXFLOAT.fullmatch(text):
        digits, _, power = body.lstrip("+-")[2:].lower().partition("p")
        whole, _, fraction = digits.partition(".")
        mantissa, exponent = int(whole + fraction or "0", 16), int(power or "0") - 4 * len(fraction)
        zero = mantissa == 0

        def exact() -> Fraction:
            return sign * Fraction(mantissa) * Fraction(2) ** exponent
        if zero or exponent + mantissa.bit_length() < -1100:
            value = sign * 0.0
        elif exponent + mantissa.bit_length() > 1100:
            value = sign * math.inf
        else:
            try:
                value = float(exact())
            except OverflowError:
                value = sign * math.inf
    elif _INFNAN.fullmatch(text):
        word = body.lstrip("+-").lower()
        value = float("nan") if word.startswith("nan") else float("inf")
        return -value if body.startswith("-") else value
    else:
        return None
    if math.isinf(value):
        return None                                             # ERANGE: overflow
    if not zero and abs(value) < sys.float_info.min and (value == 0.0 or Fraction(value) != exact()):
        return None                                             # ERANGE: underflow, inexact
    return value


# ---- the store -----------------------------------------------------------------------------------
@dataclass
class _Variant:
    """``rcl_variant_t``: one slot per type; a new value fills its type's slot only."""

    slots: dict[str, Any] = field(default_factory=dict)

    def value(self) -> Value:
        for kind in TYPES:
            if kind in self.slots:
                return Value(kind, self.slots[kind])
        return Value("not set", None)


@dataclass
class _NodeEntry:
    name: str
    names: list[str] = field(default_factory=list)
    values: list[_Variant] = field(default_factory=list)

    def find(self, parameter: str) -> int:
        """``find_parameter``: the index of ``parameter``, added when new."""
        for i, name in enumerate(self.names):
            if name == parameter:
                return i
        self.names.append(parameter)
        self.values.append(_Variant())
        return len(self.names) - 1


class ParameterStore:
    """Parameter overrides by node name, as rcl's ``rcl_params_t`` holds them (module
    docstring): fill it with ``parse_file``, ``parse_text`` and ``set_rule``; read it
    with ``for_node`` or ``get``."""

    def __init__(self) -> None:
        self._nodes: list[_NodeEntry] = []

    def _node(self, name: str) -> int:
        """``find_node``: the index of node entry ``name``, added when new."""
        for i, entry in enumerate(self._nodes):
            if entry.name == name:
                return i
        self._nodes.append(_NodeEntry(name))
        return len(self._nodes) - 1

    @property
    def node_names(self) -> list[str]:
        """The node names, in the order first seen."""
        return [entry.name for entry in self._nodes]

    def get(self, node: str, parameter: str) -> Value | None:
        """The value stored for ``parameter`` of node entry ``node`` (as written: "/**",
        "some_node"), or None."""
        for entry in self._nodes:
            if entry.name == node:
                for name, variant in zip(entry.names, entry.values, strict=True):
                    if name == parameter:
                        return variant.value()
        return None

    def items(self) -> list[tuple[str, str, Value]]:
        """Every (node name, parameter, value), in the store's order."""
        return [(entry.name, name, variant.value()) for entry in self._nodes
                for name, variant in zip(entry.names, entry.values, strict=True)]

    def for_node(self, fully_qualified_name: str) -> dict[str, Value]:
        """The parameters of the node ``fully_qualified_name`` (module docstring)."""
        out: dict[str, Value] = {}
        for entry in self._nodes:
            name = entry.name if entry.name.startswith("/") else "/" + entry.name
            pattern = name.replace("/*", r"(/\w+)")
            if re.fullmatch(pattern, fully_qualified_name, re.ASCII):
                for parameter, variant in zip(entry.names, entry.values, strict=True):
                    out[parameter] = variant.value()
        return out

    def sources_for(self, fully_qualified_name: str) -> list[str]:
        """The node names of the entries that apply to ``fully_qualified_name``."""
        return [entry.name for entry in self._nodes
                if re.fullmatch((entry.name if entry.name.startswith("/") else "/" + entry.name)
                                .replace("/*", r"(/\w+)"), fully_qualified_name, re.ASCII)]

    # ---- filling ---------------------------------------------------------------------------------
    def set_rule(self, node: str, parameter: str, yaml_value: str) -> None:
        """``rcl_parse_yaml_value``: ``parameter`` of node entry ``node`` from the YAML
        text ``yaml_value`` (a scalar or a flat sequence); ``ParameterError`` otherwise."""
        if not node or not parameter or not yaml_value:
            raise ParameterError("a parameter rule needs a node, a name and a value")
        entry = self._nodes[self._node(node)]
        variant = entry.values[entry.find(parameter)]
        is_seq, seq_type = False, None
        for event in _events(yaml_value):
            kind = type(event).__name__
            if kind == "ScalarEvent":
                seq_type = _set_value(variant, event, is_seq, seq_type)
            elif kind == "SequenceStartEvent":
                is_seq, seq_type = True, None
            elif kind == "SequenceEndEvent":
                is_seq = False
            elif kind not in ("StreamStartEvent", "StreamEndEvent", "DocumentStartEvent",
                              "DocumentEndEvent"):
                raise ParameterError(f"{yaml_value!r} is not a scalar or a list of scalars")

    def parse_file(self, path: str | Path) -> None:
        """``rcl_parse_yaml_file``: the parameter file at ``path`` into the store;
        ``ParameterError`` naming the file and the line."""
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise ParameterError(f"--params-file {path}: cannot read it ({exc.strerror or exc})") from None
        self.parse_text(text, str(path))

    def parse_text(self, text: str, source: str = "<text>") -> None:
        """The parameter file ``text`` (from ``source``, for messages) into the store."""
        try:
            _parse_file_events(_events(text), self)
        except ParameterError as exc:
            raise ParameterError(f"--params-file {source}: {exc}") from None


def _events(text: str) -> list[Any]:
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)     # libyaml, as rcl reads it
    try:
        return list(yaml.parse(text, Loader=loader))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" near line {mark.line + 1}" if mark is not None else ""
        raise ParameterError(f"not YAML{where}: {getattr(exc, 'problem', None) or exc}") from None


def _line(event: Any) -> int:
    return int(event.start_mark.line) + 1


def _set_value(variant: _Variant, event: Any, is_seq: bool, seq_type: str | None) -> str | None:
    """``parse_value``: one scalar into ``variant``; the sequence's type after it."""
    if event.style not in ("'", '"') and not event.value:
        raise ParameterError(f"no value at line {_line(event)}")
    kind, value = scalar_value(event.value, event.style, event.tag)
    if not is_seq:
        variant.slots[kind] = value
        return seq_type
    if seq_type is None:
        variant.slots[kind + "_array"] = []
    elif seq_type != kind:
        raise ParameterError(f"a list's values must all be of one type: {event.value!r} ({kind}) "
                             f"at line {_line(event)} is not a {seq_type}")
    variant.slots[kind + "_array"].append(value)
    return kind


_NODE_LEVEL, _PARAMS_LEVEL = 1, 2


class _Tracker:
    """``namespace_tracker_t``: the node namespace ('/'-joined) and the parameter
    namespace ('.'-joined), each with its count of names."""

    def __init__(self) -> None:
        self.ns: dict[str, str | None] = {"node": None, "param": None}
        self.count = {"node": 0, "param": 0}

    def add(self, kind: str, name: str) -> None:
        sep = "/" if kind == "node" else "."
        current = self.ns[kind]
        if self.count[kind] == 0 or current is None:
            self.ns[kind] = name
        else:
            self.ns[kind] = current + ("" if current.endswith(sep) else sep) + name
        self.count[kind] += 1

    def remove(self, kind: str) -> None:
        sep = "/" if kind == "node" else "."
        if self.count[kind] > 0:
            current = self.ns[kind]
            if self.count[kind] == 1 or current is None:
                self.ns[kind] = None
            elif sep in current:
                self.ns[kind] = current[:current.rindex(sep)]
            self.count[kind] -= 1

    def replace(self, kind: str, name: str, count: int) -> None:
        self.ns[kind], self.count[kind] = name, count


def _validate_name(name: str) -> None:
    """``_validate_name``: a node name of a parameter file (``/**`` and ``/*`` as whole
    components allowed)."""
    if name in ("/**", "/*"):
        return
    cut = name.rfind("/")
    node, namespace = (name, None) if cut < 0 else (name[cut + 1:], name[:cut + 1])
    if namespace is not None:
        namespace = namespace if namespace.startswith("/") else "/" + namespace
        parts = [p for p in re.split(r"(?=/)", namespace) if p]      # "/a/b/" -> /a, /b, /
        for part in parts[:-1]:
            if part == "/":
                raise ParameterError(f"{name!r} contains repeated forward slash")
            if part in ("/**", "/*"):
                continue
            why = validate_namespace(part)
            if why:
                raise ParameterError(f"node name {name!r}: {why}")
    if node not in ("*", "**"):
        why = validate_node_name(node)
        if why:
            raise ParameterError(f"node name {name!r}: {why}")


def _parse_file_events(events: list[Any], store: ParameterStore) -> None:
    """``parse_file_events``, line for line (module docstring)."""
    is_key, is_seq, is_new_map = True, False, False
    seq_type: str | None = None
    map_level, map_depth = _NODE_LEVEL, 0
    tracker = _Tracker()
    node_idx, param_idx = 0, 0
    nodes = store._nodes
    for event in events:
        kind = type(event).__name__
        line = _line(event)
        if kind == "ScalarEvent":
            if is_key:
                value = event.value
                if not value:
                    raise ParameterError(f"no key at line {line}")
                if map_level == _NODE_LEVEL:
                    if not value.startswith(PARAMS_KEY):
                        tracker.add("node", value)
                    else:
                        if tracker.count["node"] == 0 or tracker.ns["node"] is None:
                            raise ParameterError(f"no node name before {PARAMS_KEY} at line {line}")
                        _validate_name(tracker.ns["node"])
                        node_idx = store._node(tracker.ns["node"])
                        tracker.remove("node")
                        map_level += 1
                else:
                    entry = nodes[node_idx]
                    if is_new_map:
                        tracker.replace("param", entry.names[param_idx], tracker.count["param"] + 1)
                        is_new_map = False
                    prefix = tracker.ns["param"]
                    if prefix is None:
                        param_idx = entry.find(value)
                    else:
                        param_idx = entry.find(prefix)
                        entry.names[param_idx] = f"{prefix}.{value}"
                is_key = False
            else:
                if map_level < _PARAMS_LEVEL or not nodes or not nodes[node_idx].names:
                    raise ParameterError(f"a value before {PARAMS_KEY} at line {line}")
                seq_type = _set_value(nodes[node_idx].values[param_idx], event, is_seq, seq_type)
                if not is_seq:
                    is_key = True
        elif kind == "SequenceStartEvent":
            if is_key or map_level < _PARAMS_LEVEL:
                raise ParameterError(f"a list can only be a parameter's value (line {line})")
            is_seq, seq_type = True, None
        elif kind == "SequenceEndEvent":
            is_seq, is_key = False, True
        elif kind == "MappingStartEvent":
            map_depth += 1
            is_new_map, is_key = True, True
            if map_level == _PARAMS_LEVEL and map_depth - (tracker.count["node"] + 1) == 2:
                is_new_map = False
        elif kind == "MappingEndEvent":
            if map_level == _PARAMS_LEVEL:
                if tracker.count["param"] > 0:
                    tracker.remove("param")
                else:
                    map_level -= 1
            elif map_level == _NODE_LEVEL and map_depth == tracker.count["node"] + 1:
                tracker.remove("node")
            map_depth -= 1
        elif kind == "AliasEvent":
            raise ParameterError(f"aliases are not supported (line {line})")


# ---- -p rules ----------------------------------------------------------------------------------------
def parse_param_rule(text: str) -> tuple[str, str, str]:
    """(node, name, YAML value) of the ``-p`` rule ``text``, ``[node:]name:=value``; the
    node is "/**" when none is named (``_rcl_parse_param_rule``: a name is tokens and
    '/' joined by '.'; no wildcards)."""
    lx = Lookahead(text)
    node = "/**"
    try:
        if lx.peek() == TOKEN and lx.peek(1) == COLON:
            node = lx.accept()
            lx.accept()
        start = lx.position
        _param_name_token(lx)
        while lx.peek() != SEPARATOR:
            lx.expect(DOT, "expected '.' or ':=' in the parameter name")
            _param_name_token(lx)
        name = text[start:lx.position]
        lx.accept()
    except RosNameError as exc:
        raise ParameterError(f"parameter rule {text!r}: {exc}") from None
    return node, name, lx.rest()


def _param_name_token(lx: Lookahead) -> None:
    kind = lx.peek()
    if kind in (WILD_ONE, WILD_MULTI):
        raise RosNameError("wildcards are not implemented in rcl")
    if kind not in (TOKEN, FORWARD_SLASH):
        lx.expect(TOKEN, "expected a parameter name")
    while lx.peek() in (TOKEN, FORWARD_SLASH):
        lx.accept()
