"""ROS 2 parameter files and values as rcl 9.2's ``rcl_yaml_param_parser`` reads them
(``wcdrive.ros2.params``), held to rcl's own fixtures and expectations
(``rcl_yaml_param_parser/test/*.yaml``, ``test_parse_yaml.cpp``), and the node
matching of rclpy (``_populate_node_parameters_from_rcl_params``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.ros2.params import ParameterError, ParameterStore, Value, parse_param_rule, scalar_value

#: rcl_yaml_param_parser/test/correct_config.yaml (rcl 9.2).
CORRECT_CONFIG = """\
# config/test_yaml
---

lidar_ns:
  lidar_1:
    ros__parameters:
      id: 10
      name: front_lidar
      ports: [2438, 2439, 2440]
      driver1:
        dx: 4.56
        dy: 2.30
        fr_sensor_specs: [12, 3, 0, 7]
        bk_sensor_specs: [12.1, -2.3, 5.2, 9.0]
      is_front: true
      driver2:
        dx: 1.23
        dy: 0.45
  lidar_2:
    ros__parameters:
      id: 992147483647
      name: back_lidar
      dy1: 0.003
      is_back: false
      driver:
        dz: 7.89
camera:
  ros__parameters:
    name: camera1
    loc: front
    cam_spec:
      angle: 2.34
      supported_brands: ["Bosch", "Novatek", "Mobius"]
new_camera_ns:
  new_camera1:
    ros__parameters:
      is_cam_on: [true, true, false, true, false, false]
      brand: Bosch
  new_camera2:
    ros__parameters:
      camera_dr:
        dr_name: default
      brand: Mobius
drive_px:
  ros__parameters:
    num_cores: 6
    arch: ARM
intel:
  ros__parameters:
    num_cores: 8
    arch: x86_64
string_tag:
  ros__parameters:
    string_bool: !!str yes
    string_int: !!str 1234
    string_double: !!str 12.34
"""
#: rcl_yaml_param_parser/test/overlay.yaml.
OVERLAY = """\
lidar_ns:
  lidar_2:
    ros__parameters:
      is_back: true
camera:
  ros__parameters:
    loc: back
intel:
  ros__parameters:
    num_cores: 12
"""


def store_of(*texts: str) -> ParameterStore:
    store = ParameterStore()
    for text in texts:
        store.parse_text(text)
    return store


def test_correct_config_then_overlay_then_values() -> None:
    """``test_yaml_parse_yaml``: the two files, then ``rcl_parse_yaml_value`` overrides."""
    s = store_of(CORRECT_CONFIG, OVERLAY)
    assert s.get("lidar_ns/lidar_2", "is_back") == Value("bool", True)
    assert s.get("lidar_ns/lidar_2", "id") == Value("integer", 992147483647)
    assert s.get("camera", "loc") == Value("string", "back")
    assert s.get("camera", "cam_spec.angle") == Value("double", 2.34)
    assert s.get("intel", "num_cores") == Value("integer", 12)
    assert s.get("intel", "arch") == Value("string", "x86_64")
    assert s.get("new_camera_ns/new_camera1", "is_cam_on") == Value("bool_array",
                                                                  [True, True, False, True, False, False])
    assert s.get("lidar_ns/lidar_1", "ports") == Value("integer_array", [2438, 2439, 2440])
    assert s.get("lidar_ns/lidar_1", "driver1.bk_sensor_specs") == Value("double_array",
                                                                          [12.1, -2.3, 5.2, 9.0])
    assert s.get("camera", "cam_spec.supported_brands") == Value("string_array",
                                                                 ["Bosch", "Novatek", "Mobius"])
    for name, text in (("string_bool", "yes"), ("string_int", "1234"), ("string_double", "12.34")):
        assert s.get("string_tag", name) == Value("string", text)
    for node, name, yaml_value, expected in (
            ("lidar_ns/lidar_2", "is_back", "false", Value("bool", False)),
            ("lidar_ns/lidar_2", "id", "12", Value("integer", 12)),
            ("camera", "loc", "front", Value("string", "front")),
            ("camera", "cam_spec.angle", "2.2", Value("double", 2.2)),
            ("intel", "num_cores", "8", Value("integer", 8)),
            ("intel", "arch", "x86", Value("string", "x86")),
            ("new_camera_ns/new_camera1", "is_cam_on", "[false, true]", Value("bool_array", [False, True])),
            ("lidar_ns/lidar_1", "ports", "[8080]", Value("integer_array", [8080])),
            ("lidar_ns/lidar_1", "driver1.bk_sensor_specs", "[1.0]", Value("double_array", [1.0])),
            ("camera", "cam_spec.supported_brands", "[Mobius]", Value("string_array", ["Mobius"])),
            ("initial_params_node", "category", "'0'", Value("string", "0"))):
        s.set_rule(node, name, yaml_value)
        assert s.get(node, name) == expected, name
    assert s.node_names[:3] == ["lidar_ns/lidar_1", "lidar_ns/lidar_2", "camera"]


#: rcl_yaml_param_parser/test/ fixtures that rcl refuses (``EXPECT_FALSE(res)``), as
#: there (their comment lines and unused tails left out), and why.
REFUSED = {
    "empty_name_in_ns.yaml": ("lidar_ns//lidar_w:\n  ros__parameters:\n    id: 10\n",
                              "repeated forward slash"),
    "indented_name_space.yaml": ("---\n  lidar_ns:\n  lidar_1:\n    ros__parameters:\n      id: 10\n",
                                 "before ros__parameters"),
    "no_alias_support.yaml": ('lidar_ns:\n  lidar_1:\n    ros__parameters:\n      id: 10\n'
                              '      name: &FL "front_lidar"\n      spec: *FL\n', "aliases"),
    "no_value1.yaml": ('lidar_ns:\n  lidar_1:\n    ros__parameters:\n      id:\n      name: "front lidar"\n',
                       "no value at line 4"),
    "params_with_no_node.yaml": ("node1:\n  ros__parameters:\n    name: test\nros__parameters:\n  id: 10\n",
                                 "no node name"),
    "seq_map1.yaml": ("lidar_ns:\n  lidar_1:\n    ros__parameters:\n      - driver: front_driver\n"
                      "        dx: 4.56\n", ""),
    "seq_map2.yaml": ("lidar_ns:\n  lidar_1:\n    ros__parameters:\n      id: 10\n      name: front_lidar\n"
                      "      - driver: front_driver\n        dx: 4.56\n", "YAML"),
    "wildcards_node_slash.yaml": ("/foo:\n  /*:\n    ros__parameters:\n      id: 10\n",
                                  "repeated forward slash"),
    "wildcards_partial_01.yaml": ("/foo**:\n  ros__parameters:\n    id: 10\n", "not allowed"),
    "wildcards_partial_05.yaml": ("/*foo:\n  ros__parameters:\n    id: 10\n", "not allowed"),
    "wildcards_partial_12.yaml": ("/**/n*ode:\n  ros__parameters:\n    id: 10\n", "not allowed"),
    "a list of two types": ("a:\n  ros__parameters:\n    x: [foo, 4.56]\n", "one type"),
    "a value before ros__parameters": ("a:\n  b: 1\n", "before ros__parameters"),
}


@pytest.mark.parametrize("fixture", REFUSED)
def test_what_rcl_refuses(fixture: str) -> None:
    text, why = REFUSED[fixture]
    with pytest.raises(ParameterError, match=why or None):
        store_of(text)


def test_what_rcl_takes() -> None:
    # empty_string.yaml, special_float.yaml, string_array_with_quoted_number.yaml, root_ns.yaml
    s = store_of('a:\n  ros__parameters:\n    s: ""\n',
                 "test_node:\n  ros__parameters:\n"
                 "    isstring: [string, .nananan, .nAN, .Nan, .infinf, .INf, .infinity]\n"
                 "    nan_inf: [1.1, 2.2, .nan, .NAN, .inf, +.Inf, -.INF]\n",
                 'initial_params_node:\n  ros__parameters:\n    sa1: ["Four", "score"]\n'
                 '    sa2: ["and", "7"]\n',
                 "/:\n  my_node:\n    ros__parameters:\n      param_name: 'value'\n")
    assert s.get("a", "s") == Value("string", "")
    assert s.get("test_node", "isstring") == Value("string_array", ["string", ".nananan", ".nAN", ".Nan",
                                                                    ".infinf", ".INf", ".infinity"])
    nan_inf = s.get("test_node", "nan_inf")
    assert nan_inf is not None and nan_inf.type == "double_array"
    assert nan_inf.value[:2] == [1.1, 2.2] and all(math.isnan(v) for v in nan_inf.value[2:4])
    assert nan_inf.value[4:] == [math.inf, math.inf, -math.inf]
    assert s.get("initial_params_node", "sa2") == Value("string_array", ["and", "7"])
    assert s.get("/my_node", "param_name") == Value("string", "value")


@pytest.mark.parametrize(("text", "expected"), [
    ("1", ("integer", 1)), ("1.0", ("double", 1.0)), ("true", ("bool", True)), ("Off", ("bool", False)),
    ("y", ("bool", True)), ("0x1f", ("integer", 31)), ("010", ("integer", 8)), ("08", ("double", 8.0)),
    ("-7", ("integer", -7)), ("+5", ("integer", 5)), ("1e3", ("double", 1000.0)), (".5", ("double", 0.5)),
    ("5.", ("double", 5.0)), ("0x1p3", ("double", 8.0)), ("inf", ("double", math.inf)),
    ("-.inf", ("double", -math.inf)), ("1e999", ("string", "1e999")), ("1_000", ("string", "1_000")),
    ("~", ("string", "~")), ("null", ("string", "null")),
    ("9223372036854775808", ("double", 9.223372036854776e18)),
    ("1e", ("string", "1e")), ("0x", ("string", "0x")), ("base_link", ("string", "base_link")),
    # glibc's strtod sets ERANGE on an inexact underflow and on overflow (checked with a C
    # program calling strtod as rcl does): such a text is a string
    ("1e-310", ("string", "1e-310")), ("5e-324", ("string", "5e-324")), ("0x1p-1074", ("double", 5e-324)),
    ("0x1p-1075", ("string", "0x1p-1075")), ("2.2250738585072014e-308", ("double", 2.2250738585072014e-308)),
    ("0x1.fffffffffffff8p1023", ("string", "0x1.fffffffffffff8p1023")), ("0x.8", ("double", 0.5)),
])
def test_scalars_are_typed_as_rcl_types_them(text: str, expected: tuple[str, Any]) -> None:
    assert scalar_value(text) == expected


def test_quoted_and_tagged_scalars_are_strings() -> None:
    assert scalar_value("1", "'") == ("string", "1") and scalar_value("true", '"') == ("string", "true")
    assert scalar_value("1", None, "tag:yaml.org,2002:str") == ("string", "1")
    assert scalar_value("nan")[0] == "double" and math.isnan(scalar_value("nan")[1])


def test_a_value_of_another_type_does_not_clear_the_old_one() -> None:
    """rcl's variant keeps one slot per type: a file's double, then ``-p ...:=20``, reads
    as the integer (bool, integer, double, string: the first set wins), and a later
    double does not win back over it."""
    s = store_of("n:\n  ros__parameters:\n    publish_rate: 50.0\n")
    s.set_rule("n", "publish_rate", "20")
    assert s.get("n", "publish_rate") == Value("integer", 20)
    s.set_rule("n", "publish_rate", "30.0")
    assert s.get("n", "publish_rate") == Value("integer", 20)


def test_nested_keys_join_with_dots_and_a_later_file_overrides() -> None:
    """A flat key seen again is the same entry, overwritten; a nested one seen again is
    a second entry of the same name (rcl renames entries as it descends), and rclpy
    takes the later: either way the later file wins for the node."""
    s = store_of("n:\n  ros__parameters:\n    linear:\n      x:\n        max_velocity: 1.0\n"
                 "        min_velocity: -0.5\n    angular:\n      z:\n        max_velocity: 2.0\n"
                 "    publish_rate: 50.0\n",
                 "n:\n  ros__parameters:\n    linear:\n      x:\n        max_velocity: 0.5\n"
                 "    publish_rate: 20.0\n")
    assert [(name, v.value) for _, name, v in s.items()] == [
        ("linear.x.max_velocity", 1.0), ("linear.x.min_velocity", -0.5), ("angular.z.max_velocity", 2.0),
        ("publish_rate", 20.0), ("linear.x.max_velocity", 0.5)]
    assert {name: v.value for name, v in s.for_node("/n").items()} == {
        "linear.x.max_velocity": 0.5, "linear.x.min_velocity": -0.5, "angular.z.max_velocity": 2.0,
        "publish_rate": 20.0}


def test_rclpy_matches_node_names_with_wildcards() -> None:
    s = store_of("/**:\n  ros__parameters:\n    a: 1\n    b: 1\n",
                 "/*:\n  ros__parameters:\n    b: 2\n",
                 "wheelchair_controller:\n  ros__parameters:\n    c: 3\n",
                 "/robot:\n  wheelchair_controller:\n    ros__parameters:\n      d: 4\n",
                 "/**/wheelchair_controller:\n  ros__parameters:\n    e: 5\n",
                 "/*/wheelchair_controller:\n  ros__parameters:\n    f: 6\n")
    values = {name: v.value for name, v in s.for_node("/wheelchair_controller").items()}
    assert values == {"a": 1, "b": 2, "c": 3, "e": 5}
    values = {name: v.value for name, v in s.for_node("/robot/wheelchair_controller").items()}
    assert values == {"a": 1, "b": 1, "d": 4, "e": 5, "f": 6}
    assert {name for name in s.for_node("/other")} == {"a", "b"}
    assert s.sources_for("/wheelchair_controller") == ["/**", "/*", "wheelchair_controller",
                                                       "/**/wheelchair_controller"]


def test_entries_apply_in_the_stores_order_not_the_files() -> None:
    """A ``-p`` rule for every node goes into the ``/**`` entry; a node's own entry seen
    after it still wins (rclpy applies entries in the order first seen)."""
    s = store_of("/**:\n  ros__parameters:\n    x: 1\n", "n:\n  ros__parameters:\n    x: 2\n")
    node, name, value = parse_param_rule("x:=3")
    s.set_rule(node, name, value)
    assert s.for_node("/n")["x"] == Value("integer", 2)


def test_param_rules() -> None:
    assert parse_param_rule("node:foo.bar:=[1, 2]") == ("node", "foo.bar", "[1, 2]")
    qos_rule = parse_param_rule("qos_overrides./foo/bar.history:=keep_last")
    assert qos_rule[1] == "qos_overrides./foo/bar.history"
    assert parse_param_rule("a:=b:=c") == ("/**", "a", "b:=c")
    for bad in ("foo*:=1", "1a:=1", "a..b:=1", ":=1", "a"):
        with pytest.raises(ParameterError):
            parse_param_rule(bad)
    s = ParameterStore()
    with pytest.raises(ParameterError):
        s.set_rule("/**", "a", "{b: 1}")


def test_a_file_that_cannot_be_read_is_named(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match=r"nowhere\.yaml: cannot read it"):
        ParameterStore().parse_file(tmp_path / "nowhere.yaml")
    (tmp_path / "bad.yaml").write_text("n:\n  ros__parameters:\n    x:\n")
    with pytest.raises(ParameterError, match=r"bad\.yaml: no value at line 3"):
        ParameterStore().parse_file(tmp_path / "bad.yaml")


_names = st.from_regex(r"[a-z][a-z0-9]{0,4}(_[a-z0-9]{1,3}){0,2}", fullmatch=True)
#: Doubles that read back as doubles: not subnormal (glibc's strtod sets ERANGE for
#: those, and rcl then takes the text for a string; ``test_scalars_are_typed_as_rcl_types_them``),
#: and not NaN, which equals nothing.
_doubles = st.floats(allow_nan=False).filter(lambda v: v == 0 or abs(v) >= 2.3e-308)
_values = st.one_of(
    st.builds(Value, st.just("bool"), st.booleans()),
    st.builds(Value, st.just("integer"), st.integers(-2**63, 2**63 - 1)),
    st.builds(Value, st.just("double"), _doubles),
    st.builds(Value, st.just("string"),
              st.text(st.characters(min_codepoint=32, max_codepoint=126) | st.just("é"), max_size=12)),
    st.builds(Value, st.just("integer_array"), st.lists(st.integers(-10**6, 10**6), min_size=1, max_size=4)),
    st.builds(Value, st.just("double_array"), st.lists(_doubles, min_size=1, max_size=4)),
    st.builds(Value, st.just("string_array"), st.lists(_names, min_size=1, max_size=4)),
)


@given(st.dictionaries(st.lists(_names, min_size=1, max_size=3).map(".".join), _values, min_size=1,
                       max_size=6), _names)
def test_values_written_as_yaml_read_back_the_same_from_a_file_and_from_rules(
        params: dict[str, Value], node: str) -> None:
    """Round trip: each value written as YAML (``Value.yaml``) reads back with its type,
    from a parameter file (nested keys as maps) and from ``-p`` rules."""
    # a key is a map or a value, not both
    flat = {k: v for k, v in params.items() if not any(other.startswith(k + ".") for other in params)}
    lines = [f"{node}:", "  ros__parameters:"]
    for name, value in flat.items():
        *parents, leaf = name.split(".")
        for depth, parent in enumerate(parents):
            lines.append("    " + "  " * depth + f"{parent}:")
        lines.append("    " + "  " * len(parents) + f"{leaf}: {value.yaml()}")
    store = store_of("\n".join(lines) + "\n")
    got = store.for_node("/" + node)
    assert got == flat
    rules = ParameterStore()
    for name, value in flat.items():
        rules.set_rule(*parse_param_rule(f"{node}:{name}:={value.yaml()}"))
    assert rules.for_node("/" + node) == flat
