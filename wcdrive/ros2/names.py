"""ROS 2 names and remap rules as rcl reads them (ROS 2 Jazzy: rcl 9.2, rmw 7.3). Pure:
no I/O.

- ``lex``: rcl's lexer (``rcl/src/rcl/lexer.c``, the state machine in its comment): a
  token is ``(([a-zA-Z](_)?)|_)([0-9a-zA-Z](_)?)*``, ``__node``/``__name``, ``__ns``,
  ``~/``, ``:``, ``:=``, ``/``, ``.``, ``*``, ``**``, ``\\1``…``\\9``,
  ``rostopic://``, ``rosservice://``.
- ``parse_remap`` (``_rcl_parse_remap_rule`` in ``rcl/src/rcl/arguments.c``):
  ``[node:](__node:=NAME | __ns:=/NS | [rostopic://|rosservice://]MATCH:=REPLACEMENT)``;
  wildcards and back-references are refused as rcl refuses them ("not implemented").
- ``expand_topic_name`` (``rcl/src/rcl/expand_topic_name.c``): ``~`` is the node's
  private namespace, ``{node}``, ``{ns}``/``{namespace}`` are substituted, a relative
  name is put in the node's namespace.
- ``validate_topic_name`` (``rcl/src/rcl/validate_topic_name.c``, before expansion),
  ``validate_full_topic_name``, ``validate_namespace``, ``validate_node_name``
  (``rmw/src/validate_*.c``).
- ``NodeNames``: what ``rcl_node_init`` does with the rules (``rcl/src/rcl/node.c``):
  the first ``__node`` rule whose node prefix (if any) is the node's given name renames
  it; then the first ``__ns`` rule whose prefix is the (new) name moves it; each topic
  is expanded with the node's final name and namespace, then the first topic rule whose
  prefix is that name and whose expanded match equals the expanded topic replaces it
  (its replacement expanded the same way), and the result is validated
  (``rcl_node_resolve_name`` in ``rcl/src/rcl/node_resolve_name.c``; ``rcl_remap_*`` in
  ``rcl/src/rcl/remap.c``).

A rule that rcl refuses raises ``RosNameError`` (a ``WcdriveFileError``) saying why.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from wcdrive.errors import WcdriveFileError

__all__ = ["Lookahead", "NodeNames", "RemapRule", "RosNameError", "expand_topic_name", "lex", "parse_remap",
           "validate_full_topic_name", "validate_namespace", "validate_node_name", "validate_topic_name"]

#: rmw's limits (``rmw/include/rmw/validate_*.h``): a topic name's length (255 less 8
#: reserved for the DDS prefixes), a namespace's (2 less) and a node name's.
TOPIC_MAX_LENGTH = 255 - 8
NAMESPACE_MAX_LENGTH = TOPIC_MAX_LENGTH - 2
NODE_NAME_MAX_LENGTH = 255


class RosNameError(WcdriveFileError):
    """A name or a remap rule that rcl would refuse (the message says which and why)."""


# ---- the lexer ---------------------------------------------------------------------------
#: Lexeme kinds (``rcl_lexeme_t``).
EOF, NONE, TILDE_SLASH, URL_SERVICE, URL_TOPIC, COLON, NODE, NS, SEPARATOR = (
    "EOF", "NONE", "TILDE_SLASH", "URL_SERVICE", "URL_TOPIC", "COLON", "NODE", "NS", "SEPARATOR")
BACKREF, TOKEN, FORWARD_SLASH, WILD_ONE, WILD_MULTI, DOT = (
    "BACKREF", "TOKEN", "FORWARD_SLASH", "WILD_ONE", "WILD_MULTI", "DOT")

#: The lexer's state machine as ordered alternatives (the first that matches at a
#: position wins, as the machine's one path does): ``rostopic:`` without ``//`` falls
#: back to a token, ``__`` must go on to ``ns``, ``node`` or ``name``, and a token
#: ends after one trailing ``_`` (``a__b`` is the two tokens ``a_`` and ``_b``).
_TOKEN = r"[A-Za-z][A-Za-z0-9]*(?:_[A-Za-z0-9]+)*_?|_(?!_)(?:[A-Za-z0-9]+(?:_[A-Za-z0-9]+)*_?)?"
_LEXEMES: tuple[tuple[str, re.Pattern[str]], ...] = tuple((kind, re.compile(pattern)) for kind, pattern in (
    (URL_TOPIC, r"rostopic://"), (URL_SERVICE, r"rosservice://"), (TILDE_SLASH, r"~/"),
    (NS, r"__ns"), (NODE, r"__node|__name"), (SEPARATOR, r":="), (COLON, r":"),
    (BACKREF, r"\\[1-9]"), (WILD_MULTI, r"\*\*"), (WILD_ONE, r"\*"), (FORWARD_SLASH, r"/"),
    (DOT, r"\."), (TOKEN, _TOKEN)))


def lex(text: str) -> list[tuple[str, str]]:
    """``text`` as rcl's lexer cuts it: (kind, text) pairs, ending with ``(EOF, "")``
    or, where no lexeme starts, ``(NONE, the rest)``."""
    out: list[tuple[str, str]] = []
    i = 0
    while i < len(text):
        for kind, pattern in _LEXEMES:
            m = pattern.match(text, i)
            if m:
                out.append((kind, m[0]))
                i = m.end()
                break
        else:
            out.append((NONE, text[i:]))
            return out
    out.append((EOF, ""))
    return out


class Lookahead:
    """rcl's ``rcl_lexer_lookahead2_t`` over ``text``: ``peek`` one or two lexemes ahead,
    ``accept`` one, ``expect`` one of a kind (``RosNameError`` otherwise), ``rest``."""

    def __init__(self, text: str) -> None:
        self.text, self.lexemes, self.i = text, lex(text), 0

    def peek(self, n: int = 0) -> str:
        """The kind of the lexeme ``n`` ahead."""
        j = min(self.i + n, len(self.lexemes) - 1)
        return self.lexemes[j][0]

    def accept(self) -> str:
        """Takes the next lexeme (not past the end); its text."""
        kind, text = self.lexemes[self.i]
        if kind not in (EOF, NONE):
            self.i += 1
        return text

    def expect(self, kind: str, what: str) -> str:
        """Takes the next lexeme, which must be of ``kind`` (``RosNameError``: ``what``)."""
        if self.peek() != kind:
            raise RosNameError(f"{what}, found {self.rest()!r}" if self.rest() else f"{what}, found the end")
        return self.accept()

    @property
    def position(self) -> int:
        """How many characters of ``text`` were taken."""
        return sum(len(t) for _, t in self.lexemes[:self.i])

    def rest(self) -> str:
        """The text not yet taken."""
        return self.text[self.position:]


# ---- remap rules ---------------------------------------------------------------------------
@dataclass(frozen=True)
class RemapRule:
    """One rule: ``kind`` "name" (a topic and/or service rule: ``topic``, ``service``),
    "node" (``__node:=``) or "namespace" (``__ns:=``); ``node``: the node it is for
    (``node:`` prefix) or None for every node; ``match`` (name rules) and
    ``replacement`` as written."""

    kind: str
    replacement: str
    match: str | None = None
    node: str | None = None
    topic: bool = True
    service: bool = True
    text: str = field(default="", compare=False)

    def __str__(self) -> str:
        return self.text or (f"{self.node + ':' if self.node else ''}"
                             f"{ {'node': '__node', 'namespace': '__ns'}.get(self.kind, self.match)}"
                             f":={self.replacement}")


def parse_remap(text: str) -> RemapRule:
    """The rule ``text`` (module docstring), or ``RosNameError`` saying why rcl refuses it
    (``_rcl_parse_remap_begin_remap_rule``)."""
    try:
        return _parse_remap(text)
    except RosNameError as exc:
        raise RosNameError(f"remap rule {text!r}: {exc}") from None


def _parse_remap(text: str) -> RemapRule:
    lx = Lookahead(text)
    node = None
    if lx.peek() == TOKEN and lx.peek(1) == COLON:
        node = lx.accept()
        lx.accept()
    kind = lx.peek()
    if kind == NODE:
        lx.accept()
        lx.expect(SEPARATOR, "expected ':=' after __node")
        if lx.peek() != TOKEN:
            raise RosNameError(f"node name not remapped to invalid name {lx.rest()!r}")
        name = lx.accept()
        lx.expect(EOF, "expected the end after the node name")
        return RemapRule("node", name, node=node, text=text)
    if kind == NS:
        lx.accept()
        lx.expect(SEPARATOR, "expected ':=' after __ns")
        start = lx.position
        if lx.peek() != FORWARD_SLASH:
            raise RosNameError(f"namespace not remapped to a fully qualified name (found {lx.rest()!r})")
        lx.accept()
        while lx.peek() == TOKEN:                       # token ('/' token)* with a trailing '/'
            lx.accept()
            if lx.peek() != FORWARD_SLASH:
                break
            lx.accept()
        if lx.peek() != EOF:
            raise RosNameError(f"namespace not remapped to a fully qualified name "
                               f"(found {text[start:]!r})")
        return RemapRule("namespace", text[start:], node=node, text=text)
    topic = service = True
    if kind == URL_SERVICE:
        topic = False
        lx.accept()
    elif kind == URL_TOPIC:
        service = False
        lx.accept()
    start = _name(lx, _match_token, SEPARATOR, "expected '/' or ':=' in the name to match")
    match = text[start:lx.position]
    lx.accept()                                         # :=
    start = _name(lx, _replacement_token, EOF, "expected '/' or the end in the replacement")
    return RemapRule("name", text[start:], match=match, node=node, topic=topic, service=service, text=text)


def _name(lx: Lookahead, token: Callable[[Lookahead], None], end: str, message: str) -> int:
    """A name of ``token``s joined by ``/`` (after an optional leading ``~/`` or ``/``)
    up to ``end``, the match side's ``:=`` or the replacement's end; returns where it
    started."""
    start = lx.position
    if lx.peek() in (TILDE_SLASH, FORWARD_SLASH):
        lx.accept()
    token(lx)
    while lx.peek() != end:
        lx.expect(FORWARD_SLASH, message)
        token(lx)
    return start


def _match_token(lx: Lookahead) -> None:
    kind = lx.peek()
    if kind in (WILD_ONE, WILD_MULTI):
        raise RosNameError(f"wildcard {'*' if kind == WILD_ONE else '**'!r} is not implemented in rcl")
    lx.expect(TOKEN, "expected a name token")


def _replacement_token(lx: Lookahead) -> None:
    if lx.peek() == BACKREF:
        raise RosNameError("back-references are not implemented in rcl")
    lx.expect(TOKEN, "expected a name token in the replacement")


# ---- validation ------------------------------------------------------------------------------
def validate_topic_name(name: str) -> str | None:
    """Why rcl refuses topic name ``name`` before expansion (``~``, ``{}`` allowed), or
    None (``rcl_validate_topic_name``)."""
    if not name:
        return "topic name must not be empty"
    if name[0].isdigit():
        return "topic name must not start with a number"
    if name.endswith("/"):
        return "topic name must not end with a forward slash"
    brace = None
    for i, c in enumerate(name):
        if c.isascii() and c.isalnum():
            if c.isdigit() and brace is not None and i - 1 == brace:
                return "substitution name must not start with a number"
        elif c in "_":
            pass
        elif c == "/":
            if brace is not None:
                return "substitution contains characters that are not allowed"
        elif c == "~":
            if i != 0:
                return "tilde is only allowed as the first character"
        elif c == "{":
            if brace is not None:
                return "substitution contains characters that are not allowed"
            brace = i
        elif c == "}":
            if brace is None:
                return "unmatched curly brace"
            brace = None
        else:
            return ("substitution contains characters that are not allowed" if brace is not None
                    else f"topic name contains {c!r}, which is not allowed")
    if brace is not None:
        return "unmatched curly brace"
    for i in range(len(name) - 1):
        if name[i] == "/":
            if name[i + 1].isdigit():
                return "name token must not start with a number"
        elif i == 1 and name[0] == "~":
            return "tilde must be followed by a forward slash"
    return None


def validate_full_topic_name(name: str) -> str | None:
    """Why rmw refuses the fully qualified topic name ``name``, or None
    (``rmw_validate_full_topic_name``)."""
    if not name:
        return "topic name must not be empty"
    if name[0] != "/":
        return "topic name must be absolute, it must lead with a '/'"
    if name.endswith("/"):
        return "topic name must not end with a forward slash"
    for c in name:
        if not (c.isascii() and c.isalnum()) and c not in "_/":
            return f"topic name contains {c!r}, which is not allowed"
    for i in range(len(name) - 1):
        if name[i] == "/" and name[i + 1] == "/":
            return "topic name must not contain repeated '/'"
        if name[i] == "/" and name[i + 1].isdigit():
            return "topic name token must not start with a number"
    if len(name) > TOPIC_MAX_LENGTH:
        return f"topic name is longer than {TOPIC_MAX_LENGTH} characters"
    return None


def validate_namespace(namespace: str) -> str | None:
    """Why rmw refuses node namespace ``namespace``, or None (``rmw_validate_namespace``)."""
    if namespace == "/":
        return None
    why = validate_full_topic_name(namespace)
    if why is not None and not why.startswith("topic name is longer"):
        return why.replace("topic name", "namespace")
    if len(namespace) > NAMESPACE_MAX_LENGTH:
        return f"namespace is longer than {NAMESPACE_MAX_LENGTH} characters"
    return None


def validate_node_name(name: str) -> str | None:
    """Why rmw refuses node name ``name``, or None (``rmw_validate_node_name``)."""
    if not name:
        return "node name must not be empty"
    for c in name:
        if not (c.isascii() and c.isalnum()) and c != "_":
            return f"node name contains {c!r}, which is not allowed (only letters, digits, '_')"
    if name[0].isdigit():
        return "node name must not start with a number"
    if len(name) > NODE_NAME_MAX_LENGTH:
        return f"node name is longer than {NODE_NAME_MAX_LENGTH} characters"
    return None


def expand_topic_name(name: str, node: str, namespace: str) -> str:
    """``name`` as a fully qualified name for node ``node`` in ``namespace``
    (``rcl_expand_topic_name``); ``RosNameError`` for an invalid name or an unknown
    substitution."""
    for why in (validate_topic_name(name), validate_node_name(node), validate_namespace(namespace)):
        if why:
            raise RosNameError(f"cannot expand {name!r}: {why}")
    if name.startswith("/") and "{" not in name:
        return name
    out = name
    if name.startswith("~"):
        out = (namespace if namespace == "/" else namespace + "/") + node + name[1:]
    while "{" in out:
        sub = out[out.index("{"):out.index("}") + 1]
        value = {"{node}": node, "{ns}": namespace, "{namespace}": namespace}.get(sub)
        if value is None:
            raise RosNameError(f"cannot expand {name!r}: unknown substitution {sub}")
        out = out.replace(sub, value)
    if not out.startswith("/"):
        out = (namespace if namespace == "/" else namespace + "/") + out
    return out


# ---- a node's names -----------------------------------------------------------------------------
@dataclass(frozen=True)
class NodeNames:
    """A node's final name and namespace, its topic rules, and the name it was created
    with (``given``; module docstring); build it with ``NodeNames.init``."""

    name: str
    namespace: str
    rules: tuple[RemapRule, ...] = ()
    given: str = ""

    @classmethod
    def init(cls, name: str, namespace: str = "/", rules: Iterable[RemapRule] = ()) -> NodeNames:
        """The node ``name`` in ``namespace`` after ``rules`` (``rcl_node_init``):
        a namespace without a leading '/' gets one; ``RosNameError`` for an invalid name
        or namespace, given or remapped."""
        rules = tuple(rules)
        given = name
        why = validate_node_name(name)
        if why:
            raise RosNameError(f"node name {name!r}: {why}")
        namespace = namespace or "/"
        if not namespace.startswith("/"):
            namespace = "/" + namespace
        why = validate_namespace(namespace)
        if why:
            raise RosNameError(f"node namespace {namespace!r}: {why}")
        rule = _first(rules, "node", name)
        if rule is not None:
            name = rule.replacement
            why = validate_node_name(name)
            if why:
                raise RosNameError(f"remap rule {str(rule)!r}: {why}")
        rule = _first(rules, "namespace", name)
        if rule is not None:
            namespace = rule.replacement
            why = validate_namespace(namespace)
            if why:     # rcl keeps "/ns/" but no topic of the node can then be expanded in it
                raise RosNameError(f"remap rule {str(rule)!r}: {why}")
        return cls(name, namespace, rules, given)

    @property
    def fully_qualified_name(self) -> str:
        """``/namespace/name``."""
        return (self.namespace if self.namespace == "/" else self.namespace + "/") + self.name

    def resolve(self, topic: str, service: bool = False) -> str:
        """The fully qualified name of ``topic`` as this node creates it: expanded, then
        remapped by the first matching rule, then validated (``rcl_node_resolve_name``)."""
        expanded = expand_topic_name(topic, self.name, self.namespace)
        for rule in self.rules:
            if rule.kind != "name" or not (rule.service if service else rule.topic):
                continue
            if rule.node is not None and rule.node != self.name:
                continue
            try:
                match = expand_topic_name(rule.match or "", self.name, self.namespace)
            except RosNameError:
                continue
            if match == expanded:
                expanded = expand_topic_name(rule.replacement, self.name, self.namespace)
                break
        why = validate_full_topic_name(expanded)
        if why:
            raise RosNameError(f"topic {topic!r} resolves to {expanded!r}: {why}")
        return expanded


def _first(rules: Sequence[RemapRule], kind: str, node: str) -> RemapRule | None:
    for rule in rules:
        if rule.kind == kind and (rule.node is None or rule.node == node):
            return rule
    return None
