"""ROS 2's arguments and names as rcl reads them (``wcdrive.ros2.rosargs``,
``wcdrive.ros2.names``), held to the cases of rcl's own tests (rcl 9.2, ROS 2 Jazzy:
``rcl/test/rcl/test_lexer.cpp``, ``test_arguments.cpp``, ``test_remap.cpp``,
``test_expand_topic_name.cpp``), and a round trip of generated rules."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.ros2.names import (
    BACKREF,
    EOF,
    NONE,
    NS,
    TOKEN,
    URL_SERVICE,
    URL_TOPIC,
    NodeNames,
    RosNameError,
    expand_topic_name,
    lex,
    parse_remap,
    validate_topic_name,
)
from wcdrive.ros2.params import Value
from wcdrive.ros2.rosargs import RosArgumentsError, parse_arguments


# ---- the lexer (test_lexer.cpp: the first lexeme of a text) ---------------------------------
@pytest.mark.parametrize(("kind", "first", "text"), [
    (TOKEN, "foo", "foo"), (TOKEN, "foo", "foo:"), (TOKEN, "foo_", "foo_"), (TOKEN, "foo_", "foo_:"),
    (TOKEN, "_", "_"), (NONE, "@", "@"), (NONE, "{", "{"), (NONE, "0", "0"), (NONE, "9", "9"),
    (TOKEN, "_abcd", "_abcd"), (TOKEN, "abcd_", "abcd_"), (TOKEN, "ab_cd", "ab_cd"),
    (TOKEN, "_a_b_c_d_", "_a_b_c_d_"), (TOKEN, "_a_", "_a__bcd"), (TOKEN, "a_", "a__bcd"),
    (TOKEN, "A_", "A__bcd"), (NONE, "__a", "__a"), (NONE, "__A", "__A"), (TOKEN, "_0_", "_0_"),
    (TOKEN, "a0a", "a0a"), (TOKEN, "_9", "_9"), (TOKEN, "ros", "ros"), (TOKEN, "rosservice", "rosservice"),
    (TOKEN, "rosservice", "rosservice:"), (TOKEN, "rosservice", "rosservice:="),
    (TOKEN, "rosservice", "rosservice:/"), (TOKEN, "rosservice", "rosservice:/a"),
    (TOKEN, "rostopic", "rostopic:/a"), (TOKEN, "_GHI_", "_GHI_"),
    (URL_SERVICE, "rosservice://", "rosservice://abcd"), (URL_TOPIC, "rostopic://", "rostopic:///"),
    (BACKREF, "\\1", "\\1a"), (NS, "__ns", "__ns"), ("NODE", "__node", "__node"),
    ("NODE", "__name", "__name"),
    ("TILDE_SLASH", "~/", "~/"), ("SEPARATOR", ":=", ":="), ("COLON", ":", ":"), ("WILD_MULTI", "**", "**"),
    ("WILD_ONE", "*", "*"), ("FORWARD_SLASH", "/", "/"), ("DOT", ".", "."), (EOF, "", ""),
])
def test_the_lexer_cuts_as_rcls(kind: str, first: str, text: str) -> None:
    got_kind, got_text = lex(text)[0]
    assert got_kind == kind
    if kind != NONE:
        assert got_text == first


# ---- the argument grammar (test_arguments.cpp) -------------------------------------------------
def known(*argv: str) -> bool:
    """rcl's ``are_known_ros_args``: parses, and nothing is left over."""
    try:
        _, rest = parse_arguments(list(argv))
    except RosArgumentsError:
        return False
    return rest == []


@pytest.mark.parametrize("rule", [
    "__node:=node_name", "old_name:__node:=node_name", "old_name:__node:=nodename123",
    "__node:=nodename123", "__ns:=/foo/bar", "__ns:=/", "_:=kq", "nodename:__ns:=/foobar", "foo:=bar",
    "~/foo:=~/bar", "/foo/bar:=bar", "foo:=/bar", "/foo123:=/bar123", "node:/foo123:=/bar123",
    "rostopic:=/foo/bar", "rosservice:=baz", "rostopic://rostopic:=rosservice",
    "rostopic:///rosservice:=rostopic", "rostopic:///foo/bar:=baz",
])
def test_the_remap_rules_rcl_knows(rule: str) -> None:
    assert known("--ros-args", "-r", rule)


@pytest.mark.parametrize("argv", [
    ["-p", "foo:=bar"], ["-p", "qos_overrides./foo/bar.publisher.history:=keep_last"],
    ["-p", "foo.bar:=bar"], ["-p", "node:foo:=bar"], ["-p", "fizz123:=buzz456"],
    ["--log-config-file", "file.config"], ["--log-level", "UNSET"], ["--log-level", "debug"],
    ["--log-level", "Info"], ["--log-file-name", "filename"], ["--enable-rosout-logs"],
    ["--disable-stdout-logs"], ["--enable-external-lib-logs"], ["-e", "/enclave"],
])
def test_the_other_ros_arguments_rcl_knows(argv: list[str]) -> None:
    assert known("--ros-args", *argv)


@pytest.mark.parametrize("argv", [
    ["--custom-ros-arg"], ["__node:=node_name"], ["old_name:__node:=node_name"], ["/foo/bar:=bar"],
    ["foo:=/bar"], ["file_name.yaml"], ["--log", "foo"], ["--loglevel", "foo"],
    ["--logfile-name", "filename"], ["stdout-logs"],
])
def test_unknown_ros_arguments_are_refused_as_rclpy_refuses_them(argv: list[str]) -> None:
    """rcl parses them as unknown ROS arguments; rclpy then refuses to start."""
    with pytest.raises(RosArgumentsError, match="unknown ROS arguments"):
        parse_arguments(["--ros-args", *argv])


@pytest.mark.parametrize("argv", [
    ["-r"], ["--remap"], ["-r", ":"], ["-r", "1"], ["-r", "~"], ["-r", ":="], ["-r", "foo:="],
    ["-r", ":=bar"],
    ["-r", "::="], ["-r", "1:="], ["-r", "~:="], ["-r", "__node:="], ["-r", "__node:=/foo/bar"],
    ["-r", "__ns:="], ["-r", "__ns:=foo"], ["-r", ":__node:=nodename"], ["-r", "~:__node:=nodename"],
    ["-r", "}foo:=/bar"], ["-r", "f oo:=/bar"], ["-r", "foo:=/b ar"], ["-r", "f{oo:=/bar"],
    ["-r", "foo:=/b}ar"], ["-r", "rostopic://:=rosservice"], ["-r", "rostopic::=rosservice"],
    ["-p"], ["-p", ":="], ["-p", "foo:="], ["-p", ":=bar"], ["-p", ":"], ["-p", "1"], ["-p", "~"],
    ["-p", "::="], ["-p", "1:="], ["-p", "~:="], ["-p", "__node:="], ["-p", "__node:=/foo/bar"],
    ["-p", "__ns:=foo"], ["-p", ":__node:=nodename"], ["-p", "~:__node:=nodename"], ["-p", "}foo:=/bar"],
    ["--param", "}foo:=/bar"], ["-p", "f oo:=/bar"], ["--param", "f oo:=/bar"], ["-e"], ["--enclave"],
    ["--params-file"], ["--log-config-file"], ["--log-level"], ["--log-level", "foo"], ["--log-file-name"],
    ["-r", "foo/*:=bar"], ["-r", "foo:=\\1"], ["-p", "a:={b: 1}"],
])
def test_invalid_ros_arguments_are_refused(argv: list[str]) -> None:
    with pytest.raises(RosArgumentsError, match="couldn't parse"):
        parse_arguments(["--ros-args", *argv])


def test_blocks_end_at_double_dash_and_the_rest_comes_back_in_order() -> None:
    """``test_remove_ros_args`` and ``test_mix_valid_invalid_rules``."""
    ros, rest = parse_arguments(["-d", "--ros-args", "-r", "__ns:=/foo/bar", "-r", "__ns:=/fiz/buz", "--",
                                 "--foo=bar", "--baz", "--ros-args", "--ros-args", "-p", "bar:=baz", "--",
                                 "--", "arg"])
    assert rest == ["-d", "--foo=bar", "--baz", "--", "arg"]
    assert [r.replacement for r in ros.remaps] == ["/foo/bar", "/fiz/buz"]
    assert ros.parameters.get("/**", "bar") is not None
    assert parse_arguments(["--ros-args", "--"])[1] == []
    assert parse_arguments(["--ros-args", "-r", "/foo/bar:=/fiz/buz", "--", "--"])[1] == ["--"]
    with pytest.raises(RosArgumentsError) as caught:
        parse_arguments(["--ros-args", "/foo/bar:=", "-r", "bar:=/fiz/buz", "}bar:=fiz", "--", "arg"])
    assert "['/foo/bar:=', '}bar:=fiz']" in str(caught.value)


def test_a_bare_remap_rule_outside_a_block_is_rcls_deprecated_form() -> None:
    ros, rest = parse_arguments(["sim://", "foo:=bar", "--seconds", "1"])
    assert rest == ["sim://", "--seconds", "1"]
    assert [str(r) for r in ros.remaps] == ["foo:=bar"] and "deprecated" in ros.warnings[0]


def test_param_overrides_from_files_and_rules_merge_in_order(tmp_path: Path) -> None:
    """``test_param_overrides``: the file's ``some_node``, then ``-p`` rules for every
    node (``/**``) and for ``some_node``."""
    path = tmp_path / "test_parameters.1.yaml"
    path.write_text("some_node:\n  ros__parameters:\n    int_param: 1\n    param_group:\n"
                    "      string_param: foo\n")
    ros, _ = parse_arguments(["--ros-args", "--params-file", str(path), "--param", "string_param:=bar",
                              "-p", "some.bool_param:=false", "-p", "some_node:int_param:=4"])
    store = ros.parameters
    assert store.node_names == ["some_node", "/**"]
    assert store.get("/**", "string_param") == Value("string", "bar")
    assert store.get("/**", "some.bool_param") == Value("bool", False)
    assert store.get("some_node", "int_param") == Value("integer", 4)
    assert store.get("some_node", "param_group.string_param") == Value("string", "foo")
    assert ros.param_files == [str(path)]


# ---- remap rules and names (test_remap.cpp, test_expand_topic_name.cpp) ---------------------------
def names(*rules: str, node: str = "NodeName", namespace: str = "/") -> NodeNames:
    return NodeNames.init(node, namespace, [parse_remap(r) for r in rules])


def test_namespace_and_node_rules() -> None:
    assert names("__ns:=/foo/bar").namespace == "/foo/bar"
    for node, expected in (("Node1", "/foo/bar"), ("Node2", "/this_one"), ("Node3", "/bar/foo")):
        n = names("Node1:__ns:=/foo/bar", "Node2:__ns:=/this_one", "Node3:__ns:=/bar/foo", node=node)
        assert n.namespace == expected
    assert names().namespace == "/"
    assert names("/foobar:=/foo/bar", "__ns:=/namespace", "__node:=new_name").namespace == "/namespace"
    assert names("__node:=globalname").name == "globalname"
    assert names("__node:=firstname", "__node:=secondname").name == "firstname"
    assert names("__ns:=/namespace", "__node:=remap_name", "/foobar:=/foo/bar").name == "remap_name"
    # the namespace rule is matched against the new name (rcl_node_init)
    assert names("__node:=renamed", "renamed:__ns:=/moved").namespace == "/moved"
    assert names("__node:=renamed", "NodeName:__ns:=/moved").namespace == "/"
    assert names(node="n", namespace="ns").namespace == "/ns"


def test_topic_rules() -> None:
    assert names("/bar/foo:=/foo/bar").resolve("/bar/foo") == "/foo/bar"
    assert names("/bar/foo:=/foo/bar").resolve("/foo/bar") == "/foo/bar"
    assert names("foo:=bar", namespace="/ns").resolve("foo") == "/ns/bar"
    for node, expected in (("Node1", "/foo/bar"), ("Node2", "/this_one"), ("Node3", "/bar/foo")):
        n = names("Node1:/foo:=/foo/bar", "Node2:/foo:=/this_one", "Node3:/foo:=/bar/foo", node=node)
        assert n.resolve("/foo") == expected
    other_rules_first = names("__ns:=/namespace", "__node:=remap_name", "/foobar:=/foo/bar")
    assert other_rules_first.resolve("/foobar") == "/foo/bar"
    assert names("rosservice://foo:=bar").resolve("foo") == "/foo"                 # a service rule only
    assert names("rosservice://foo:=bar").resolve("foo", service=True) == "/bar"
    assert names("rostopic://foo:=bar").resolve("foo") == "/bar"
    assert names("rostopic://foo:=bar").resolve("foo", service=True) == "/foo"
    assert names("~/odom:=odometry", node="ctl").resolve("~/odom") == "/odometry"
    assert names("/first:=/a", "/first:=/b").resolve("/first") == "/a"            # the first rule wins
    with pytest.raises(RosNameError):
        names("__ns:=/ns/").resolve("foo")


@pytest.mark.parametrize(("topic", "node", "namespace", "expected"), [
    ("/chatter", "my_node", "/my_ns", "/chatter"), ("chatter", "my_node", "/my_ns", "/my_ns/chatter"),
    ("{node}/chatter", "my_node", "/my_ns", "/my_ns/my_node/chatter"),
    ("/{node}", "my_node", "/my_ns", "/my_node"),
    ("{node}", "my_node", "/my_ns", "/my_ns/my_node"), ("{ns}", "my_node", "/my_ns", "/my_ns"),
    ("{namespace}", "my_node", "/my_ns", "/my_ns"),
    ("{namespace}/{node}/chatter", "my_node", "/my_ns", "/my_ns/my_node/chatter"),
    ("/foo/{namespace}", "my_node", "/my_ns", "/foo//my_ns"), ("ping", "my_node", "/", "/ping"),
    ("ping", "my_node", "/my_ns", "/my_ns/ping"), ("/ping", "my_node", "/", "/ping"),
    ("~", "my_node", "/", "/my_node"), ("~", "my_node", "/my_ns", "/my_ns/my_node"),
    ("~/ping", "my_node", "/", "/my_node/ping"), ("~/ping", "my_node", "/my_ns", "/my_ns/my_node/ping"),
])
def test_expand_topic_name(topic: str, node: str, namespace: str, expected: str) -> None:
    assert expand_topic_name(topic, node, namespace) == expected


@pytest.mark.parametrize("topic", ["", "1foo", "foo/", "~foo", "f~oo", "{foo", "foo}", "{1a}", "foo/2bar",
                                   "f oo", "{a/b}"])
def test_invalid_topic_names(topic: str) -> None:
    assert validate_topic_name(topic) is not None


def test_unknown_substitutions_and_bad_names_are_refused() -> None:
    with pytest.raises(RosNameError, match="unknown substitution"):
        expand_topic_name("{foo}", "n", "/")
    with pytest.raises(RosNameError):
        NodeNames.init("1node")
    with pytest.raises(RosNameError):
        NodeNames.init("node", "/a//b")


# ---- round trip ------------------------------------------------------------------------------------
_tokens = st.from_regex(r"[A-Za-z][A-Za-z0-9]{0,5}(_[A-Za-z0-9]{1,3}){0,2}", fullmatch=True)


@st.composite
def _rules(draw: st.DrawFn) -> tuple[str, dict[str, object]]:
    node = draw(st.none() | _tokens)
    kind = draw(st.sampled_from(["name", "node", "namespace"]))
    prefix = f"{node}:" if node else ""
    if kind == "node":
        name = draw(_tokens)
        return f"{prefix}__node:={name}", {"kind": "node", "replacement": name, "node": node}
    if kind == "namespace":
        ns = "/" + "/".join(draw(st.lists(_tokens, max_size=3)))
        return f"{prefix}__ns:={ns}", {"kind": "namespace", "replacement": ns, "node": node}

    def name_of() -> str:
        lead = draw(st.sampled_from(["", "/", "~/"]))
        return lead + "/".join(draw(st.lists(_tokens, min_size=1, max_size=3)))

    scheme = draw(st.sampled_from(["", "rostopic://", "rosservice://"]))
    match, replacement = name_of(), name_of()
    return (f"{prefix}{scheme}{match}:={replacement}",
            {"kind": "name", "match": match, "replacement": replacement, "node": node,
             "topic": scheme != "rosservice://", "service": scheme != "rostopic://"})


@given(_rules(), st.lists(st.sampled_from(["--seconds", "3", "sim://", "--twist", "-x"]), max_size=4))
def test_generated_rules_parse_back_to_what_was_written(rule: tuple[str, dict[str, object]],
                                                        others: list[str]) -> None:
    text, expected = rule
    parsed = parse_remap(text)
    for key, value in expected.items():
        assert getattr(parsed, key) == value, (text, key)
    assert str(parsed) == text
    ros, rest = parse_arguments([*others, "--ros-args", "-r", text, "--", *others])
    assert rest == [*others, *others] and ros.remaps == [parsed]
