"""The decision-network rule-file language: vocabulary, syntax tree and the checking loader.

A rule file describes a *decision network* in the sense of [seed 002, appendix F, "Simulation of
a marine guidance and expert collision avoidance system"]: a set of nodes, each holding a boolean
test, two children (one taken when the test holds, one when it does not), a flag per child saying
whether the child is actioned at once or at the next decision step, and the parameters of the
consequent action. This module knows nothing about collision avoidance: the caller supplies the
:class:`Vocabulary` (feature names, enum constants, action fields) that a file may use.

:func:`parse` checks the *whole* file against the vocabulary and reports every problem it finds
(unknown names with "did you mean" suggestions, missing children, loops of immediate edges,
unreachable nodes, wrong types, unknown keys, unsupported schema versions) as one
:class:`~trafficsim.errors.ScenarioError` whose text lists each problem as ``file:line: key:
message``. A file may ``extends:`` another: it then takes the other's nodes and parameters and
overrides or adds some; every problem is located in the file where the faulty text is, and every
node remembers the file it is written in. The language is documented in ``docs/rules.md``.
"""

from __future__ import annotations

import difflib
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NoReturn

from trafficsim.errors import ScenarioError
from trafficsim.io.yamlio import (
    Document,
    finite_number,
    format_loc,
    number_hint,
    parse_yaml,
    read_bytes,
    read_file,
    shown,
)

__all__ = [
    "OPERATORS",
    "SCHEMA_VERSION",
    "ActionField",
    "AllOf",
    "AnyOf",
    "Comparison",
    "Edge",
    "Literal",
    "Node",
    "Not",
    "Operand",
    "RuleSet",
    "Test",
    "Vocabulary",
    "parse",
    "parse_file",
    "read_rules",
    "render_test",
]

SCHEMA_VERSION = 1
"""The rule-file schema version this module reads."""

OPERATORS = ("<", "<=", ">", ">=", "==", "!=", "between")
"""Comparison operators, in the order of their compiled op codes."""

_TOP_KEYS = ("schema_version", "name", "description", "extends", "start", "parameters",
             "nodes")
_NODE_KEYS = ("description", "test", "yes", "no", "action")
_EDGE_KEYS = ("to", "next")
_COMBINATORS = ("all", "any", "not")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_YAML_SUFFIXES = (".yaml", ".yml")
_OPERATOR_ALIASES = {"=<": "<=", "=>": ">=", "=": "==", "<>": "!=", "~=": "!=", "lt": "<",
                     "le": "<=", "gt": ">", "ge": ">=", "eq": "==", "ne": "!=",
                     "in": "between", "within": "between"}


# --------------------------------------------------------------------------------------------
# Vocabulary (supplied by the caller)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ActionField:
    """One field of a node's action, as declared by the vocabulary.

    Attributes:
        constants: the enum constants the field accepts; empty means the field takes a number
            (written as a number or a parameter name).
        description: shown in documentation and explanations.
        bounds: the smallest and largest number a numeric field takes (both allowed).
    """

    constants: tuple[str, ...] = ()
    description: str = ""
    bounds: tuple[float, float] = (-math.inf, math.inf)

    @property
    def numeric(self) -> bool:
        """True if the field takes numbers, False if it takes enum constants."""
        return not self.constants


@dataclass(frozen=True)
class EngineParameter:
    """A parameter the caller reads from a rule set itself (not only through its nodes).

    Attributes:
        description: what the caller does with it.
        above: the value must be greater than this (``at_least`` False) or not below it.
        at_least: whether ``above`` itself is allowed.
    """

    description: str
    above: float = 0.0
    at_least: bool = False

    def admits(self, value: float) -> bool:
        return value >= self.above if self.at_least else value > self.above

    @property
    def condition(self) -> str:
        return f"{'>=' if self.at_least else '>'} {self.above:g}"


@dataclass(frozen=True)
class Vocabulary:
    """The names a rule file may use; the engine attaches no meaning to any of them.

    Attributes:
        features: feature names, in the row order of the ``(n_features, m)`` array passed to
            :func:`trafficsim.colregs.network.evaluate`.
        enums: enum constant name -> its float value (comparisons and actions are float-valued,
            so ``[own_role, ==, give_way]`` compares the feature with ``enums["give_way"]``).
        actions: action field name -> :class:`ActionField`, in the row order of the merged
            action array of a decision.
        engine_parameters: parameter name -> :class:`EngineParameter`, the parameters the
            caller reads itself: a file may set them without a node using them, and their
            values are checked against the bound. Any other parameter must be used by a node.
        feature_ranges: feature name -> the smallest and largest value it takes (both may be
            infinite; NaN, "unknown", aside); a comparison no value in that range satisfies
            can never hold and is refused. Features not listed are unbounded.

    Raises:
        ValueError: duplicate or clashing names, or an action field listing an unknown constant.
    """

    features: tuple[str, ...]
    enums: Mapping[str, float] = field(default_factory=dict)
    actions: Mapping[str, ActionField] = field(default_factory=dict)
    engine_parameters: Mapping[str, EngineParameter] = field(default_factory=dict)
    feature_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "features", tuple(self.features))
        if len(set(self.features)) != len(self.features):
            raise ValueError("vocabulary: feature names must be unique")
        clash = set(self.features) & set(self.enums)
        if clash:
            raise ValueError(f"vocabulary: names used both as feature and enum: {sorted(clash)}")
        for name, value in self.enums.items():
            if not math.isfinite(float(value)):
                raise ValueError(f"vocabulary: enum constant {name!r} must be finite")
        for name, spec in self.actions.items():
            unknown = [c for c in spec.constants if c not in self.enums]
            if unknown:
                raise ValueError(f"vocabulary: action field {name!r} lists unknown enum "
                                 f"constants {unknown}")
        for name, (lo, hi) in self.feature_ranges.items():
            if name not in self.features or not lo <= hi:
                raise ValueError(f"vocabulary: feature range of {name!r} must be lo <= hi of a "
                                 "known feature")

    def enum_names(self, value: float) -> tuple[str, ...]:
        """The enum constants whose value is ``value`` (for explanations)."""
        return tuple(name for name, v in self.enums.items() if float(v) == value)


# --------------------------------------------------------------------------------------------
# Syntax tree
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Operand:
    """A value as written in the file and as resolved.

    Attributes:
        written: the number, or the parameter / enum constant name, as in the file.
        value: the resolved float.
    """

    written: str | int | float
    value: float

    def render(self) -> str:
        return str(self.written)


@dataclass(frozen=True)
class Literal:
    """The constant test ``true`` or ``false``."""

    value: bool


@dataclass(frozen=True)
class Comparison:
    """``[feature, op, value]``; for ``between`` the value is the inclusive pair ``(lo, hi)``."""

    feature: str
    op: str
    value: Operand | tuple[Operand, Operand]


@dataclass(frozen=True)
class AllOf:
    """Holds when every item holds."""

    items: tuple[Test, ...]


@dataclass(frozen=True)
class AnyOf:
    """Holds when at least one item holds."""

    items: tuple[Test, ...]


@dataclass(frozen=True)
class Not:
    """Holds when its item does not."""

    item: Test


Test = Literal | Comparison | AllOf | AnyOf | Not


@dataclass(frozen=True)
class Edge:
    """A child pointer: ``to`` is actioned in the same decision step, or at the next one."""

    to: str
    next: bool = False


@dataclass(frozen=True)
class Node:
    """One node of the network as written in the file.

    Attributes:
        name: the node's key under ``nodes``.
        test: its boolean test.
        yes, no: the child taken when the test holds / does not (None only when the test is a
            literal that can never take that branch and the file omits it).
        action: action field -> value, applied when the node is visited.
        description: free text, shown by explanations.
        line: 1-based line of the node's key in ``path``.
        path: the file the node is written in (for a rule set that extends another, the
            parent's file for an inherited node).
    """

    name: str
    test: Test
    yes: Edge | None
    no: Edge | None
    action: Mapping[str, Operand]
    description: str
    line: int
    path: str


@dataclass(frozen=True)
class RuleSet:
    """A checked rule file: nodes in file order, parameters resolved.

    Attributes:
        name, description: the file's (the description is inherited when the file has none).
        start: the entry node.
        parameters: parameter name -> value; an enum-valued parameter holds its constant's value.
        nodes: the nodes in index order: a parent's nodes first, in its file order (a node
            the child replaces keeps its place), then the nodes the child adds.
        path: the file read.
        parameter_constants: parameter name -> the enum constant it holds, for the
            enum-valued parameters only.
        files: every file read: ``path`` first, then the file it extends, and so on.
    """

    name: str
    description: str
    start: str
    parameters: Mapping[str, float]
    nodes: tuple[Node, ...]
    path: str
    parameter_constants: Mapping[str, str] = field(default_factory=dict)
    files: tuple[str, ...] = ()

    def node(self, name: str) -> Node:
        for node in self.nodes:
            if node.name == name:
                return node
        raise KeyError(name)


def render_test(test: Test) -> str:
    """The test in the file's flow syntax: ``{all: [[x, <, 3], {not: [y, ==, on]}]}``."""
    if isinstance(test, Literal):
        return "true" if test.value else "false"
    if isinstance(test, Comparison):
        if isinstance(test.value, tuple):
            lo, hi = test.value
            value = f"[{lo.render()}, {hi.render()}]"
        else:
            value = test.value.render()
        return f"[{test.feature}, {test.op}, {value}]"
    if isinstance(test, Not):
        return f"{{not: {render_test(test.item)}}}"
    word = "all" if isinstance(test, AllOf) else "any"
    return f"{{{word}: [{', '.join(render_test(t) for t in test.items)}]}}"


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

def read_rules(source: str | bytes, path: str = "<string>") -> Document:
    """Read rule-file YAML into a located :class:`~trafficsim.io.yamlio.Document`.

    The YAML reader's rules apply (duplicate keys, aliases, size cap, plain ``yes:`` / ``no:``
    keys read as text, ...); an unquoted ``!=`` or ``>`` gets a hint to quote it.

    Raises:
        ScenarioError: invalid YAML, located.
    """
    try:
        return parse_yaml(source, path)
    except ScenarioError as exc:
        # Unquoted operators that YAML reads as syntax: ``[x, !=, 1]`` (a tag), ``[x, >, 1]``
        # (a block scalar indicator).
        if exc.message.startswith("unsupported tag '!="):
            hint = '; write the operator in quotes: "!="'
        elif "found character '>' that cannot start any token" in exc.message:
            hint = '; write the operator in quotes: ">" or ">="'
        else:
            raise
        raise ScenarioError(exc.message + hint, path=exc.path, line=exc.line,
                            key=exc.key) from None


def _read_parent(child: Document, parent: str) -> Document | ScenarioError:
    """The file ``child`` extends, or the error (located at ``child``'s ``extends``, or a YAML
    error located in the parent)."""
    where = ("extends",)
    try:
        data = read_bytes(parent)
    except FileNotFoundError:
        folder = os.path.dirname(parent) or "."
        try:
            siblings = [f for f in os.listdir(folder) if f.endswith(_YAML_SUFFIXES)]
        except OSError:
            siblings = []
        hint = _close(os.path.basename(parent), siblings)
        return child.error(f"the file to extend, '{parent}', does not exist{hint}; 'extends' "
                           "takes a path relative to the folder of this file", where)
    except IsADirectoryError:
        return child.error(f"the file to extend, '{parent}', is a directory; 'extends' takes "
                           "the path of a rules file", where)
    except OSError as exc:
        return child.error(f"cannot read the file to extend, '{parent}' "
                           f"({exc.strerror or exc})", where)
    try:
        return read_rules(data, parent)
    except ScenarioError as exc:
        return exc


def _read_chain(doc: Document) -> tuple[list[Document], list[ScenarioError]]:
    """``doc`` and the files it extends, the root (a file without ``extends``) first.

    The errors are those of the chain itself: an ``extends`` that is not text, a file that
    does not exist or is not YAML, a loop. The chain ends at the first one.
    """
    chain = [doc]
    seen = [os.path.realpath(doc.path)]
    while isinstance(chain[-1].data, dict) and "extends" in chain[-1].data:
        child = chain[-1]
        written = child.data["extends"]
        if not (isinstance(written, str) and written.strip()):
            hint = " (put it in quotes)" if isinstance(written, bool | int | float) else ""
            return chain[::-1], [child.error(
                f"expected the path of the rules file this one extends, got "
                f"{shown(written)}{hint}", ("extends",))]
        parent = os.path.normpath(os.path.join(os.path.dirname(child.path), written))
        real = os.path.realpath(parent)
        if real in seen:
            trail = " -> ".join([*(d.path for d in chain[seen.index(real):]), parent])
            return chain[::-1], [child.error(
                f"extends loop: {trail}; a rules file cannot extend itself, directly or through "
                "the files it extends", ("extends",))]
        loaded = _read_parent(child, parent)
        if isinstance(loaded, ScenarioError):
            return chain[::-1], list(getattr(loaded, "errors", None) or [loaded])
        chain.append(loaded)
        seen.append(real)
    return chain[::-1], []


# --------------------------------------------------------------------------------------------
# Checking
# --------------------------------------------------------------------------------------------

def _meant(data: Mapping[str, Any], allowed: Sequence[str]) -> set[str]:
    """The allowed keys that ``data``'s unknown keys look like misspellings of (a misspelt key
    also makes the key it was meant to be missing: only the typo is reported)."""
    return {close for key in data if key not in allowed
            for close in difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)}


def _close(word: str, options: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest option, or an empty string."""
    match = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f" (did you mean '{match[0]}'?)" if match else ""


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


class _Checker:
    """Walks the loaded files once, collecting every error with its location.

    ``chain`` is a file and the files it extends, the root first: the parameters and nodes of
    later files override those of earlier ones, and the merged network is checked. A file's
    *level* is its index in ``chain``; the last file is the one being read.
    """

    def __init__(self, chain: Sequence[Document], vocabulary: Vocabulary) -> None:
        self.chain = list(chain)
        self.top = len(self.chain) - 1
        self.level = self.top
        self.doc = self.chain[-1]  # the file the current errors are located in
        self.vocab = vocabulary
        self.errors: list[ScenarioError] = []
        self.parameters: dict[str, float] = {}
        self.constants: dict[str, str] = {}  # enum-valued parameter -> its constant
        self.param_level: dict[str, int] = {}  # parameter -> the file whose value counts
        self.declared: dict[str, int] = {}  # parameter -> last file declaring it, valid or not
        self.bad_parameters: set[str] = set()  # declared but invalid: uses are not re-reported
        # parameters an extending file adds (not overrides): they must be used in that file
        self.added: dict[str, tuple[int, list[str]]] = {}  # name -> (file, inherited names)
        self.used: set[tuple[str, int]] = set()  # (parameter, file of the text using it)
        self.owner: dict[str, int] = {}  # node -> the file it is written in
        # node -> its (branch, edge) pairs; edges_ok is False once any edge is missing or
        # wrong, and the graph checks (loops, reachability) are then skipped
        self.edges: dict[str, list[tuple[str, Edge]]] = {}
        self.edges_ok = True
        self.meant: set[str] = set()  # required top-level keys the current file misspelt

    def at(self, level: int) -> None:
        """Locate the following errors in file ``level`` of the chain."""
        self.level = level
        self.doc = self.chain[level]

    def error(self, loc: Sequence[str | int], message: str) -> None:
        self.errors.append(self.doc.error(message, loc))

    def value_error(self, operands: Sequence[Any], loc: tuple[str | int, ...],
                    message: str) -> None:
        """An error about the value of parameters used at ``loc``.

        When a later file of the chain set one of the parameters (an override), the faulty
        text is that file's value, not the use: the error is located at the override and names
        the use.
        """
        later = [p for p in operands if isinstance(p, str)
                 and self.param_level.get(p, -1) > self.level]
        if not later:
            self.error(loc, message)
            return
        name = max(later, key=self.param_level.__getitem__)
        use = f"{self.doc.path}:{self.doc.line_of(loc)} ({format_loc(loc)})"
        self.errors.append(self.chain[self.param_level[name]].error(
            f"{message}; the value of '{name}' set here is used at {use}", ("parameters", name)))

    def unknown_keys(self, data: Mapping[str, Any], allowed: Sequence[str],
                     loc: tuple[str | int, ...], what: str) -> None:
        for key in data:
            if key not in allowed:
                hint = _close(key, allowed) or f"; allowed keys of {what}: {', '.join(allowed)}"
                self.error((*loc, key), f"unknown key '{key}'{hint}")

    def text(self, value: Any, loc: tuple[str | int, ...], what: str) -> str | None:
        if isinstance(value, str) and value.strip():
            return value
        hint = " (put it in quotes)" if isinstance(value, bool | int | float) else ""
        self.error(loc, f"expected {what}, got {shown(value)}{hint}")
        return None

    # ---- top level --------------------------------------------------------------------------

    def run(self) -> RuleSet | None:
        for level in range(len(self.chain)):
            self.at(level)
            self.meant = _meant(self.doc.data, _TOP_KEYS)
            if not self.schema_version(self.doc.data):
                return None
        name: str | None = None
        description = ""
        start: tuple[str | None, int] | None = None  # (name, file) of the start that counts
        nodes_data: dict[str, Any] = {}
        for level, doc in enumerate(self.chain):
            self.at(level)
            data = doc.data
            self.meant = _meant(data, _TOP_KEYS)
            self.unknown_keys(data, _TOP_KEYS, (), "a rules file")
            name = self.required_text(data, "name", "the rule set's name as text")
            if "description" in data:
                description = (self.text(data["description"], ("description",), "text")
                               or "").strip()
            self.read_parameters(data.get("parameters", {}))
            for key, value in self.read_nodes(data).items():
                self.owner[key] = level  # a node a later file writes replaces it in place
                nodes_data[key] = value
            if level == 0 or "start" in data:
                start = (self.required_text(data, "start", "the name of the entry node"), level)
        names = list(self.owner)
        entry = self.check_start(start, names)
        nodes = []
        for key in names:
            self.at(self.owner[key])
            nodes.append(self.read_node(key, nodes_data[key], names))
        self.check_added_parameters()
        self.check_unused_parameters()
        self.check_engine_parameters()
        if entry is not None and self.edges_ok:
            self.check_graph(entry, names)
        if self.errors:
            return None
        assert name is not None and entry is not None
        return RuleSet(name=name, description=description, start=entry,
                       parameters=dict(self.parameters),
                       nodes=tuple(n for n in nodes if n is not None), path=self.doc.path,
                       parameter_constants=dict(self.constants),
                       files=tuple(d.path for d in reversed(self.chain)))

    def schema_version(self, data: Mapping[str, Any]) -> bool:
        """False if the file is of a schema this module cannot read (stop checking then)."""
        if "schema_version" not in data:
            if "schema_version" in self.meant:
                return True
            self.error(("schema_version",),
                       f"missing required key 'schema_version'; expected 'schema_version: "
                       f"{SCHEMA_VERSION}' at the top of the file")
            return True
        version = data["schema_version"]
        if not (isinstance(version, int) and not isinstance(version, bool)):
            self.error(("schema_version",),
                       f"expected the whole number {SCHEMA_VERSION}, got {shown(version)}")
            return True
        if version != SCHEMA_VERSION:
            self.error(("schema_version",),
                       f"unsupported schema_version {version}; this version of trafficsim "
                       f"reads schema_version {SCHEMA_VERSION}")
            return False
        return True

    def required_text(self, data: Mapping[str, Any], key: str, what: str) -> str | None:
        if key not in data:
            if key not in self.meant:  # (a misspelt key is reported as the unknown one)
                self.error((key,), f"missing required key '{key}' ({what})")
            return None
        return self.text(data[key], (key,), what)

    def read_nodes(self, data: Mapping[str, Any]) -> dict[str, Any]:
        """The file's ``nodes`` mapping (required unless the file extends another)."""
        if "nodes" not in data:
            if self.level == 0 and "nodes" not in self.meant:
                self.error(("nodes",), "missing required key 'nodes' (a mapping of node name "
                                       "-> node)")
            return {}
        nodes = data["nodes"]
        if not isinstance(nodes, dict) or not nodes:
            got = "no nodes" if nodes == {} else shown(nodes)
            self.error(("nodes",), f"expected a non-empty mapping of node name -> node, got "
                                   f"{got}")
            return {}
        return nodes

    def check_start(self, start: tuple[str | None, int] | None, names: list[str]) -> str | None:
        if start is None or start[0] is None:
            return None
        name, level = start
        if name not in names:
            if names:
                self.at(level)
                self.error(("start",), f"unknown node '{name}'{_close(name, names)}; start "
                                       "must name a node under 'nodes'")
            return None
        return name

    # ---- parameters -------------------------------------------------------------------------

    def read_parameters(self, params: Any) -> None:
        loc: tuple[str | int, ...] = ("parameters",)
        if params is None or params == {}:
            return
        if not isinstance(params, dict):
            self.error(loc, f"expected a mapping of parameter name -> number or enum constant, "
                            f"got {shown(params)}")
            return
        inherited = list(self.declared)
        for pname, value in params.items():
            ploc = (*loc, pname)
            if not _NAME.match(pname):
                self.bad_parameters.add(pname)
                self.error(ploc, f"invalid parameter name '{pname}'; expected letters, digits "
                                 "and underscores, starting with a letter or underscore")
                continue
            if pname in self.vocab.enums or pname in self.vocab.features:
                self.bad_parameters.add(pname)
                kind = "an enum constant" if pname in self.vocab.enums else "a feature"
                self.error(ploc, f"parameter '{pname}' has the name of {kind} of the "
                                 "vocabulary; rename the parameter")
                continue
            parsed = self.parameter_value(value, ploc, params)
            if pname in inherited:
                if parsed is not None and not self.same_kind(pname, parsed[1], ploc):
                    parsed = None
            elif self.level > 0:
                self.added[pname] = (self.level, inherited)
            self.declared[pname] = self.level
            if parsed is None:
                self.bad_parameters.add(pname)
                self.parameters.pop(pname, None)
                continue
            self.bad_parameters.discard(pname)
            self.parameters[pname], constant = parsed
            self.param_level[pname] = self.level
            if constant is None:
                self.constants.pop(pname, None)
            else:
                self.constants[pname] = constant

    def parameter_value(self, value: Any, loc: tuple[str | int, ...],
                        siblings: Mapping[str, Any]) -> tuple[float, str | None] | None:
        """A parameter's value and, if it holds an enum constant, the constant (``siblings``:
        the parameters declared beside it)."""
        expected = "a parameter holds a number or an enum constant of the vocabulary"
        if _is_number(value):
            number = self.number(value, loc)
            return None if number is None else (number, None)
        if isinstance(value, str) and _NAME.match(value):
            if value in self.vocab.enums:
                return float(self.vocab.enums[value]), value
            if value in self.vocab.features:
                self.error(loc, f"'{value}' is a feature; {expected}")
            elif value in self.declared or value in siblings:
                self.error(loc, f"'{value}' is a parameter; {expected} (parameters cannot "
                                "refer to each other)")
            else:
                self.error(loc, f"unknown enum constant '{value}'"
                                f"{_close(value, list(self.vocab.enums))}; {expected}")
            return None
        self.error(loc, f"expected a number or an enum constant, got {shown(value)}"
                        f"{self.hint(loc)}")
        return None

    def same_kind(self, name: str, constant: str | None, loc: tuple[str | int, ...]) -> bool:
        """An override holds what the parameter held before: a number, or an enum constant."""
        if name not in self.param_level:
            return True  # the inherited value is invalid itself (reported there)
        before = self.constants.get(name)
        if (before is None) == (constant is None):
            return True
        doc = self.chain[self.param_level[name]]
        where = f"{doc.path}:{doc.line_of(('parameters', name))}"
        if before is None:
            self.error(loc, f"parameter '{name}' holds a number in {where}; an override must "
                            f"hold a number too, got the enum constant '{constant}'")
        else:
            self.error(loc, f"parameter '{name}' holds the enum constant '{before}' in {where}; "
                            "an override must hold an enum constant too, got a number")
        return False

    def check_added_parameters(self) -> None:
        """A parameter an extending file adds must be used by that file's own nodes: a name
        nothing uses is most likely a misspelt override, which would change nothing. Only the
        last file's are checked: an earlier file's were checked with that file last (where its
        nodes were all present; a later file may replace them)."""
        for pname, (level, inherited) in self.added.items():
            if (level != self.top or (pname, level) in self.used
                    or pname in self.bad_parameters):
                continue
            self.at(level)
            parent = self.chain[level - 1].path
            self.error(("parameters", pname),
                       f"parameter '{pname}' is not a parameter of '{parent}'"
                       f"{_close(pname, inherited)} and no node of this file uses it; a file "
                       "that extends another may override the parameters it inherits, or add "
                       "parameters for its own nodes")

    def check_unused_parameters(self) -> None:
        """A file read alone may declare only parameters its nodes use, or that the caller
        reads itself (the vocabulary's engine parameters): any other name is most likely
        misspelt, and its value would change nothing. (A file that extends another is checked
        by :meth:`check_added_parameters`; the files it extends were checked alone.) Checked
        only in an otherwise sound file: a node with an error may be the unread use."""
        if self.top != 0 or self.errors:
            return
        self.at(0)
        engine = list(self.vocab.engine_parameters)
        for pname in self.declared:
            if ((pname, 0) in self.used or pname in self.vocab.engine_parameters
                    or pname in self.bad_parameters):
                continue
            hint = _close(pname, engine)
            reads = (f"one the decision step reads ({', '.join(engine)})" if engine
                     else "read by the decision step")
            self.error(("parameters", pname),
                       f"parameter '{pname}' is used by no node and is not {reads}{hint}; "
                       "remove it or use it in a node")

    def check_engine_parameters(self) -> None:
        """The parameters the caller reads must hold numbers within their bounds; located at
        the file whose value counts."""
        for pname, spec in self.vocab.engine_parameters.items():
            if pname not in self.param_level:
                continue
            self.at(self.param_level[pname])
            if pname in self.constants:
                self.error(("parameters", pname),
                           f"parameter '{pname}' ({spec.description}) must hold a number, got "
                           f"the enum constant '{self.constants[pname]}'")
            elif not spec.admits(self.parameters[pname]):
                self.error(("parameters", pname),
                           f"parameter '{pname}' ({spec.description}) must be "
                           f"{spec.condition}, got {self.parameters[pname]:g}")
        self.at(self.top)

    def hint(self, loc: Sequence[str | int]) -> str:
        """Why the text at ``loc`` of the current file was not read as a number, if it looks
        like one (quotes, a leading zero, an exponent without a dot, ...)."""
        return number_hint(self.doc.node_at(loc))

    def number(self, value: Any, loc: tuple[str | int, ...]) -> float | None:
        """A finite number written as a number (not text, not a boolean)."""
        if _is_number(value):
            number = finite_number(value)
            if number is not None:
                return number
            self.error(loc, f"expected a finite number, got {shown(value)}")
            return None
        self.error(loc, f"expected a number, got {shown(value)}{self.hint(loc)}")
        return None

    def parameter(self, name: str) -> Operand:
        """A use of the (valid) parameter ``name`` by the current file."""
        self.used.add((name, self.level))
        return Operand(name, self.parameters[name])

    # ---- nodes ------------------------------------------------------------------------------

    def read_node(self, name: str, data: Any, names: list[str]) -> Node | None:
        """The node, or None if any part of it is wrong (errors recorded)."""
        loc: tuple[str | int, ...] = ("nodes", name)
        before = len(self.errors)
        if not _NAME.match(name):
            self.error(loc, f"invalid node name '{name}'; expected letters, digits and "
                            "underscores, starting with a letter or underscore")
        if not isinstance(data, dict):
            self.error(loc, f"expected a node (a mapping with keys test, yes, no and optional "
                            f"action, description), got {shown(data)}")
            self.edges_ok = False
            return None
        # A misspelt key also makes the key it was meant to be missing: report the typo only.
        meant = _meant(data, _NODE_KEYS)
        self.unknown_keys(data, _NODE_KEYS, loc, "a node")
        test: Test | None = None
        if "test" in data:
            test = self.read_test(data["test"], (*loc, "test"))
        elif "test" not in meant:
            self.error(loc, "missing required key 'test' (a comparison, a combination "
                            "{all: [...]}, {any: [...]}, {not: ...}, or true / false)")
        edges: dict[str, Edge | None] = {}
        raw_test = data.get("test")
        for branch, when in (("yes", "holds"), ("no", "does not hold")):
            # Which children are required depends on the test: without one, say nothing.
            dead = "test" not in data or (isinstance(raw_test, bool)
                                          and raw_test == (branch == "no"))
            if branch in data:
                edges[branch] = self.read_edge(data[branch], (*loc, branch), names)
                self.edges_ok &= edges[branch] is not None
            elif dead:
                edges[branch] = None
                self.edges_ok &= "test" in data
            else:
                self.edges_ok = False
                if branch not in meant:
                    self.error(loc, f"missing required key '{branch}' (the child actioned when "
                                    f"the test {when}: a node name or {{to: NAME, next: true}})")
        self.edges[name] = [(b, e) for b, e in edges.items() if e is not None]
        action = self.read_action(data.get("action"), (*loc, "action")) \
            if "action" in data else {}
        description = ""
        if "description" in data:
            description = self.text(data["description"], (*loc, "description"), "text") or ""
        if len(self.errors) > before or test is None or action is None:
            return None
        return Node(name=name, test=test, yes=edges.get("yes"), no=edges.get("no"),
                    action=action, description=description.strip(),
                    line=self.doc.line_of(loc), path=self.doc.path)

    def read_edge(self, value: Any, loc: tuple[str | int, ...], names: list[str]) -> Edge | None:
        expected = "expected a node name or {to: NAME, next: true|false}"
        if isinstance(value, str):
            return self.edge_target(value, False, loc, names)
        if not isinstance(value, dict):
            self.error(loc, f"{expected}, got {shown(value)}")
            return None
        self.unknown_keys(value, _EDGE_KEYS, loc, "an edge")
        nxt = value.get("next", False)
        if not isinstance(nxt, bool):
            self.error((*loc, "next"), f"expected true or false, got {shown(nxt)}")
            nxt = None
        if "to" not in value:
            if "to" not in _meant(value, _EDGE_KEYS):
                self.error(loc, f"missing required key 'to'; {expected}")
            return None
        target = self.text(value["to"], (*loc, "to"), "a node name")
        if target is None or nxt is None or any(k not in _EDGE_KEYS for k in value):
            return None
        return self.edge_target(target, nxt, (*loc, "to"), names)

    def edge_target(self, target: str, nxt: bool, loc: tuple[str | int, ...],
                    names: list[str]) -> Edge | None:
        if target not in names:
            self.error(loc, f"unknown node '{target}'{_close(target, names)}; a child must "
                            "name a node under 'nodes'")
            return None
        return Edge(target, nxt)

    def read_action(self, value: Any, loc: tuple[str | int, ...]) -> dict[str, Operand] | None:
        fields = list(self.vocab.actions)
        if not isinstance(value, dict) or not value:
            self.error(loc, f"expected a mapping of action field -> value (fields: "
                            f"{', '.join(fields) or 'none declared'}), got "
                            f"{shown(value) if value != {} else 'an empty mapping'}")
            return None
        out: dict[str, Operand] = {}
        for key, raw in value.items():
            floc = (*loc, key)
            spec = self.vocab.actions.get(key)
            if spec is None:
                hint = _close(key, fields) or f"; action fields: {', '.join(fields)}"
                self.error(floc, f"unknown action field '{key}'{hint}")
                continue
            operand = self.action_value(key, spec, raw, floc)
            if operand is not None:
                out[key] = operand
        return out if len(out) == len(value) else None

    def action_value(self, key: str, spec: ActionField, raw: Any,
                     loc: tuple[str | int, ...]) -> Operand | None:
        if isinstance(raw, str) and raw in self.bad_parameters:
            return None  # already reported where the parameter is declared
        if isinstance(raw, str) and raw in self.parameters:
            return self.parameter_in_action(key, spec, raw, loc)
        if not spec.numeric:
            allowed = ", ".join(spec.constants)
            if isinstance(raw, str) and raw in spec.constants:
                return Operand(raw, float(self.vocab.enums[raw]))
            if isinstance(raw, str):
                self.error(loc, f"unknown value '{raw}' for action field '{key}'"
                                f"{_close(raw, spec.constants)}; expected one of: {allowed}")
            else:
                self.error(loc, f"expected one of: {allowed}, got {shown(raw)}")
            return None
        if isinstance(raw, str) and _NAME.match(raw):
            if raw in self.vocab.enums:
                self.error(loc, f"'{raw}' is an enum constant, but action field '{key}' takes a "
                                "number or a parameter name")
                return None
            self.error(loc, f"unknown parameter '{raw}'{_close(raw, list(self.parameters))}; "
                            f"action field '{key}' takes a number or a parameter name")
            return None
        number = self.number(raw, loc)
        return None if number is None else self.within_bounds(key, spec, Operand(raw, number),
                                                              loc)

    def within_bounds(self, key: str, spec: ActionField, operand: Operand,
                      loc: tuple[str | int, ...]) -> Operand | None:
        """``operand`` if the numeric field ``key`` takes its value (located at a later
        file's override of the parameter, if one set it)."""
        lo, hi = spec.bounds
        if lo <= operand.value <= hi:
            return operand
        shown_value = (f"{operand.written} = {operand.value:g}"
                       if isinstance(operand.written, str) else f"{operand.value:g}")
        self.value_error([operand.written], loc,
                         f"action field '{key}' ({spec.description}) takes numbers in "
                         f"[{lo:g}, {hi:g}], got {shown_value}")
        return None

    def parameter_in_action(self, key: str, spec: ActionField, name: str,
                            loc: tuple[str | int, ...]) -> Operand | None:
        """Parameter ``name`` as the value of action field ``key``: a number for a numeric
        field, one of the field's constants for an enum field."""
        operand = self.parameter(name)
        constant = self.constants.get(name)
        if spec.numeric and constant is not None:
            self.value_error([name], loc, f"parameter '{name}' holds the enum constant "
                                          f"'{constant}', but action field '{key}' takes a "
                                          "number or a parameter holding a number")
            return None
        if spec.numeric:
            return self.within_bounds(key, spec, operand, loc)
        allowed = ", ".join(spec.constants)
        if constant is None:
            self.value_error([name], loc, f"parameter '{name}' holds a number, but action "
                                          f"field '{key}' takes one of: {allowed}")
            return None
        if constant not in spec.constants:
            self.value_error([name], loc, f"parameter '{name}' holds '{constant}', which action "
                                          f"field '{key}' does not take; expected one of: "
                                          f"{allowed}")
            return None
        return operand

    # ---- tests ------------------------------------------------------------------------------

    def read_test(self, value: Any, loc: tuple[str | int, ...]) -> Test | None:
        if isinstance(value, bool):
            return Literal(value)
        if isinstance(value, list):
            return self.read_comparison(value, loc)
        if isinstance(value, dict):
            return self.read_combination(value, loc)
        self.error(loc, "expected a test: a comparison [feature, op, value], {all: [...]}, "
                        f"{{any: [...]}}, {{not: test}}, true or false; got {shown(value)}")
        return None

    def read_combination(self, value: dict[str, Any], loc: tuple[str | int, ...]) -> Test | None:
        keys = list(value)
        if len(keys) != 1 or keys[0] not in _COMBINATORS:
            bad = [k for k in keys if k not in _COMBINATORS]
            if bad:
                self.error((*loc, bad[0]), f"unknown key '{bad[0]}'{_close(bad[0], _COMBINATORS)}"
                                           "; a test mapping has exactly one key: all, any or "
                                           "not")
            else:
                self.error(loc, f"a test mapping has exactly one key (all, any or not), got "
                                f"{', '.join(keys) or 'none'}; nest them to combine")
            return None
        word = keys[0]
        inner = value[word]
        iloc = (*loc, word)
        if word == "not":
            if isinstance(inner, list) and inner and isinstance(inner[0], list | dict):
                self.error(iloc, "not takes one test, got a list of tests; write "
                                 "{not: {all: [...]}} or {not: {any: [...]}}")
                return None
            item = self.read_test(inner, iloc)
            return None if item is None else Not(item)
        if not isinstance(inner, list) or not inner:
            got = "an empty list" if inner == [] else shown(inner)
            self.error(iloc, f"expected a non-empty list of tests, got {got}")
            return None
        if not isinstance(inner[0], list | dict | bool) and len(inner) == 3:
            self.error(iloc, f"{word} takes a list of tests, got a single comparison; write "
                             f"{{{word}: [[feature, op, value], ...]}}")
            return None
        items = [self.read_test(item, (*iloc, i)) for i, item in enumerate(inner)]
        if any(item is None for item in items):
            return None
        kept = tuple(item for item in items if item is not None)
        return AllOf(kept) if word == "all" else AnyOf(kept)

    def read_comparison(self, value: list[Any], loc: tuple[str | int, ...]) -> Test | None:
        if len(value) != 3:
            self.error(loc, f"a comparison is [feature, op, value] (3 items), got "
                            f"{len(value)} item{'s' if len(value) != 1 else ''}")
            return None
        feature, op, operand = value
        ok = True
        features = self.vocab.features
        if not isinstance(feature, str):
            self.error((*loc, 0), f"expected a feature name, got {shown(feature)}")
            ok = False
        elif feature not in features:
            self.error((*loc, 0), f"unknown feature '{feature}'{_close(feature, features)}")
            ok = False
        if not isinstance(op, str) or op not in OPERATORS:
            if isinstance(op, str):
                hint = (f" (did you mean '{_OPERATOR_ALIASES[op]}'?)"
                        if op in _OPERATOR_ALIASES else _close(op, OPERATORS))
                op_text = f"'{op}'"
            else:
                hint, op_text = "", shown(op)
            self.error((*loc, 1), f"unknown operator {op_text}{hint}; expected one of "
                                  f"{', '.join(OPERATORS)} (quote '>', '>=' and '!=' in YAML)")
            return None
        if op == "between":
            pair = self.between(operand, (*loc, 2))
            if pair is None or not ok:
                return None
            return self.satisfiable(Comparison(feature, op, pair), (*loc, 2))
        resolved = self.value(operand, (*loc, 2))
        if resolved is None or not ok:
            return None
        return self.satisfiable(Comparison(feature, op, resolved), (*loc, 2))

    def satisfiable(self, test: Comparison, loc: tuple[str | int, ...]) -> Comparison | None:
        """``test``, or None (an error at its value) when no value in the feature's range
        (:attr:`Vocabulary.feature_ranges`) satisfies it: a branch that can never be taken,
        such as ``[dcpa_nm, "<", -1]``."""
        if test.feature not in self.vocab.feature_ranges:
            return test
        lo, hi = self.vocab.feature_ranges[test.feature]
        if isinstance(test.value, tuple):  # between
            a, b = test.value
            if not (b.value < lo or a.value > hi):
                return test
            operands = [a.written, b.written]
            written = f"between [{a.render()}, {b.render()}] = [{a.value:g}, {b.value:g}]"
        else:
            v = test.value.value
            if not {"<": v <= lo, "<=": v < lo, ">": v >= hi, ">=": v > hi,
                    "==": v < lo or v > hi, "!=": False}[test.op]:
                return test
            operands = [test.value.written]
            written = f"{test.op} {test.value.render()}" + (
                f" = {v:g}" if isinstance(test.value.written, str) else "")
        self.value_error(operands, loc, f"can never hold: {test.feature} takes values from "
                                        f"{lo:g} to {hi:g}, so '{test.feature} {written}' is "
                                        "never true")
        return None

    def between(self, value: Any, loc: tuple[str | int, ...]) -> tuple[Operand, Operand] | None:
        if not isinstance(value, list) or len(value) != 2:
            got = f"{len(value)} items" if isinstance(value, list) else shown(value)
            self.error(loc, f"between expects two numbers [lo, hi] (numbers or parameter "
                            f"names), got {got}")
            return None
        lo = self.value((value[0]), (*loc, 0), enums=False)
        hi = self.value((value[1]), (*loc, 1), enums=False)
        if lo is None or hi is None:
            return None
        if lo.value > hi.value:
            self.value_error([lo.written, hi.written], loc,
                             f"between needs lo <= hi, got [{lo.render()}, {hi.render()}] = "
                             f"[{lo.value:g}, {hi.value:g}]")
            return None
        return lo, hi

    def value(self, value: Any, loc: tuple[str | int, ...], enums: bool = True) -> Operand | None:
        """A comparison value: a number, a parameter name or (if ``enums``) an enum constant."""
        expected = ("a number, a parameter name or an enum constant" if enums
                    else "a number or a parameter name")
        if isinstance(value, str) and value in self.bad_parameters:
            return None  # already reported where the parameter is declared
        if isinstance(value, str) and _NAME.match(value):
            if value in self.parameters:
                operand = self.parameter(value)
                constant = self.constants.get(value)
                if constant is not None and not enums:
                    self.value_error([value], loc, f"parameter '{value}' holds the enum "
                                                   f"constant '{constant}'; expected {expected} "
                                                   "holding a number")
                    return None
                return operand
            if value in self.vocab.enums:
                if enums:
                    return Operand(value, float(self.vocab.enums[value]))
                self.error(loc, f"'{value}' is an enum constant; expected {expected}")
                return None
            if value in self.vocab.features:
                self.error(loc, f"'{value}' is a feature; a comparison's value must be "
                                f"{expected} (features cannot be compared with each other)")
                return None
            names = list(self.parameters) + (list(self.vocab.enums) if enums else [])
            what = "parameter or enum constant" if enums else "parameter"
            self.error(loc, f"unknown {what} '{value}'{_close(value, names)}; expected "
                            f"{expected}")
            return None
        if _is_number(value):
            number = self.number(value, loc)
            return None if number is None else Operand(value, number)
        self.error(loc, f"expected {expected}, got {shown(value)}{self.hint(loc)}")
        return None

    # ---- graph ------------------------------------------------------------------------------

    def check_graph(self, start: str, names: list[str]) -> None:
        # A loop of immediate edges would never end a decision step [seed 002, appendix F:
        # each child is "actioned immediately or at the next time-step"].
        now = {name: [(b, e.to) for b, e in self.edges[name] if not e.next] for name in names}
        state: dict[str, int] = {}  # 1 = on the current depth-first path, 2 = done
        for root in names:
            if root in state:
                continue
            state[root] = 1
            stack: list[tuple[str, list[tuple[str, str]]]] = [(root, list(now[root]))]
            trail: list[tuple[str, str]] = []  # (node, branch) of each edge along the path
            while stack:
                name, todo = stack[-1]
                if not todo:
                    stack.pop()
                    state[name] = 2
                    if trail:
                        trail.pop()
                    continue
                branch, child = todo.pop(0)
                if state.get(child) == 1:
                    self.report_loop(child, [*trail, (name, branch)])
                elif child not in state:
                    state[child] = 1
                    trail.append((name, branch))
                    stack.append((child, list(now[child])))
        reached = {start}
        frontier = [start]
        while frontier:
            for _, edge in self.edges[frontier.pop()]:
                if edge.to not in reached:
                    reached.add(edge.to)
                    frontier.append(edge.to)
        # Only the file being read must reach each of its nodes: nodes of a parent that the
        # file has bypassed (by replacing the nodes that led to them) are simply never visited.
        self.at(self.top)
        for name in names:
            if name not in reached and self.owner[name] == self.top:
                self.error(("nodes", name),
                           f"node '{name}' cannot be reached from start '{start}'; link it "
                           "from another node or remove it")

    def report_loop(self, child: str, trail: list[tuple[str, str]]) -> None:
        first = next(i for i, (n, _) in enumerate(trail) if n == child)
        cycle = trail[first:]
        words = " -> ".join(f"{n} ({b})" for n, b in cycle)
        # Locate the loop at the last of its edges written in the latest file: the edge that
        # closed it (in a file that extends another, an edge of the extending file).
        name, branch = max(reversed(cycle), key=lambda edge: self.owner[edge[0]])
        self.at(self.owner[name])
        self.error(("nodes", name, branch),
                   f"loop of immediate edges: {words} -> {child}; a decision step would never "
                   "end: make one of these edges {to: NAME, next: true}")


def _raise(errors: list[ScenarioError], files: Sequence[str] = ()) -> NoReturn:
    """One error listing all, each once: ordered by file (``files`` order: the file read,
    then the file it extends, ...) then by line; the first carries path, line and key."""
    rank = {path: k for k, path in enumerate(files)}
    unique = list({(e.path, e.line, e.key, e.message): e for e in errors}.values())
    ordered = sorted(unique, key=lambda e: (rank.get(e.path or "", len(rank)),
                                            e.line if e.line is not None else 0))
    first = ordered[0]
    rest = "".join(f"\n{err}" for err in ordered[1:])
    exc = ScenarioError(first.message + rest, path=first.path, line=first.line, key=first.key)
    exc.errors = list(ordered)
    raise exc


def _check(doc: Document, vocabulary: Vocabulary) -> RuleSet:
    """Check ``doc`` and the files it extends against ``vocabulary``.

    Each file the chain extends must be a valid rules file by itself, so every prefix of the
    chain (root alone, root + next, ..., the whole chain) is checked; an error found again in
    a longer prefix, at the same place, is reported once (as the shorter prefix found it: a
    "did you mean" may differ once a later file adds names).
    """
    chain, errors = _read_chain(doc)
    files = [d.path for d in reversed(chain)]
    if errors:
        _raise(errors, files)
    rules = None
    for end in range(1, len(chain) + 1):
        checker = _Checker(chain[:end], vocabulary)
        rules = checker.run()
        found = {(e.path, e.line, e.key) for e in errors}
        errors.extend(e for e in checker.errors if (e.path, e.line, e.key) not in found)
    if errors:
        _raise(errors, files)
    assert rules is not None
    return rules


def parse(source: str | bytes, vocabulary: Vocabulary, path: str = "<string>") -> RuleSet:
    """Read and check a rule file's text against ``vocabulary``.

    Args:
        source: the YAML text (or UTF-8 bytes).
        vocabulary: the names the file may use.
        path: the file name used in messages; an ``extends:`` path is relative to its folder
            (to the working directory for a bare name such as the default ``<string>``).

    Raises:
        ScenarioError: every problem of the file and of the files it extends; its text lists
            each as ``file:line: key: message`` (the file read first, then the file it
            extends, each by line), ``path`` / ``line`` / ``key`` are the first one's, and
            ``errors`` holds them all.
    """
    return _check(read_rules(source, path), vocabulary)


def parse_file(path: str | os.PathLike[str], vocabulary: Vocabulary) -> RuleSet:
    """:func:`parse` on the content of ``path`` (at most the YAML size cap is read)."""
    return parse(read_file(path, kind="a rules YAML file"), vocabulary, os.fspath(path))
