"""Content-free inference engine of the decision network: compiler, vectorised evaluator, trace.

The network follows [seed 002, appendix F, "Simulation of a marine guidance and expert collision
avoidance system"]: each node holds a boolean test, pointers to two children, a flag per child
saying whether it is actioned immediately or at the next decision step, and the parameters of the
consequent action. The engine attaches no meaning to any name: features, enum constants and
action fields come from the caller's :class:`~trafficsim.colregs.rulefile.Vocabulary`, and the
rule file (language in ``docs/rules.md``, checking in :mod:`trafficsim.colregs.rulefile`) gives
the network.

:func:`compile_rules` turns a checked rule set into arrays: every node's test becomes a short
postfix program (op code, feature index, constants), each node gets its two child indices and
now/next flags, and the actions become a ``(n_nodes, n_action_fields)`` table with NaN where a
node does not set a field. :func:`evaluate` runs the network for all (ship, other ship) pairs
in one compiled loop and keeps the path of visited nodes, so that every decision can be
explained (the "backtracking" the paper foresees) with :func:`explain`.

Semantics for one pair and one call: start at the pair's cursor node; visit it (its action
fields overwrite those set by earlier nodes of this call: later wins); evaluate its test; take
the ``yes`` child if the test holds, else the ``no`` child; an immediate child is visited in the
same call, a ``next`` child becomes the new cursor and ends the call. A comparison whose feature
is NaN is false, whatever the operator (so ``[x, "!=", 1]`` is false for a NaN ``x`` while
``{not: [x, "==", 1]}`` is true).
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trafficsim.colregs.rulefile import (
    OPERATORS,
    ActionField,
    AllOf,
    Comparison,
    Literal,
    Not,
    Operand,
    RuleSet,
    Test,
    Vocabulary,
    parse,
    parse_file,
    render_test,
)
from trafficsim.jit import kernel

__all__ = [
    "ActionField",
    "Decision",
    "Network",
    "Vocabulary",
    "compile_rules",
    "evaluate",
    "explain",
    "load",
    "loads",
]

# Op codes of the postfix test programs. Comparisons push one boolean; the combinators pop
# ``arg`` booleans (NOT pops one) and push one.
OP_LT, OP_LE, OP_GT, OP_GE, OP_EQ, OP_NE, OP_BETWEEN = range(7)
OP_TRUE, OP_FALSE, OP_ALL, OP_ANY, OP_NOT = range(7, 12)
_OP_CODE = dict(zip(OPERATORS, range(7), strict=True))


@dataclass(frozen=True, eq=False)
class Network:
    """A compiled decision network (arrays) with the rule set it came from.

    Attributes:
        rules: the checked rule set (node names, descriptions, tests as written).
        vocabulary: the names the network was checked against.
        node_names: ``(n_nodes,)`` node names in file order; node index = position here.
        start: index of the entry node.
        code, arg: ``(n_ops,)`` int64 postfix programs of all tests, node after node; ``arg`` is
            the feature row for comparisons and the operand count for all / any.
        lo, hi: ``(n_ops,)`` float64 comparison constants (``hi`` used by between only).
        prog_start: ``(n_nodes + 1,)`` int64; node k's program is ``prog_start[k]:prog_start[k+1]``.
        child: ``(2, n_nodes)`` int64 child node of the ``no`` (row 0) and ``yes`` (row 1) branch;
            -1 for the omitted dead branch of a literal test.
        child_next: ``(2, n_nodes)`` bool, True where that child is actioned at the next step.
        actions: ``(n_nodes, n_action_fields)`` float64 action table, NaN = not set.
        max_stack: deepest value stack any test program needs.
        max_depth: most nodes one call can visit (longest chain of immediate edges + 1).
    """

    rules: RuleSet
    vocabulary: Vocabulary
    node_names: tuple[str, ...]
    start: int
    code: np.ndarray
    arg: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    prog_start: np.ndarray
    child: np.ndarray
    child_next: np.ndarray
    actions: np.ndarray
    max_stack: int
    max_depth: int

    @property
    def n_nodes(self) -> int:
        return len(self.node_names)

    @property
    def action_fields(self) -> tuple[str, ...]:
        """Action field names, in the row order of :attr:`Decision.actions`."""
        return tuple(self.vocabulary.actions)

    def node_index(self, name: str) -> int:
        """Index of the node called ``name`` (KeyError if there is none)."""
        try:
            return self.node_names.index(name)
        except ValueError:
            raise KeyError(name) from None

    def initial_cursor(self, m: int) -> np.ndarray:
        """``(m,)`` int64 cursor with every pair at the start node."""
        return np.full(m, self.start, dtype=np.int64)


@dataclass(frozen=True, eq=False)
class Decision:
    """Outcome of one decision step for ``m`` pairs.

    Attributes:
        cursor: ``(m,)`` int64 node index where each pair resumes at the next step.
        actions: ``(n_action_fields, m)`` float64 merged action fields, NaN where no visited
            node set the field.
        path: ``(m, max_depth)`` int32 visited node indices in order, -1 padded.
        path_len: ``(m,)`` int64 number of visited nodes (at least 1).
        action_fields: names of the rows of ``actions``.
    """

    cursor: np.ndarray
    actions: np.ndarray
    path: np.ndarray
    path_len: np.ndarray
    action_fields: tuple[str, ...]

    def action(self, name: str) -> np.ndarray:
        """``(m,)`` values of action field ``name`` (NaN where unset)."""
        return self.actions[self.action_fields.index(name)]


# --------------------------------------------------------------------------------------------
# Compiler
# --------------------------------------------------------------------------------------------

def _emit(test: Test, features: dict[str, int], out: list[tuple[int, int, float, float]]
          ) -> int:
    """Append the postfix program of ``test`` to ``out``; return the stack depth it needs."""
    if isinstance(test, Literal):
        out.append((OP_TRUE if test.value else OP_FALSE, 0, 0.0, 0.0))
        return 1
    if isinstance(test, Comparison):
        if isinstance(test.value, tuple):
            lo, hi = test.value[0].value, test.value[1].value
        else:
            lo = hi = test.value.value
        out.append((_OP_CODE[test.op], features[test.feature], lo, hi))
        return 1
    if isinstance(test, Not):
        depth = _emit(test.item, features, out)
        out.append((OP_NOT, 1, 0.0, 0.0))
        return depth
    # Item k is evaluated while k earlier results wait on the stack.
    depth = max(k + _emit(item, features, out) for k, item in enumerate(test.items))
    out.append((OP_ALL if isinstance(test, AllOf) else OP_ANY, len(test.items), 0.0, 0.0))
    return depth


def compile_rules(rules: RuleSet, vocabulary: Vocabulary) -> Network:
    """Compile a checked rule set (from :func:`~trafficsim.colregs.rulefile.parse`) to arrays."""
    names = tuple(node.name for node in rules.nodes)
    index = {name: k for k, name in enumerate(names)}
    features = {name: k for k, name in enumerate(vocabulary.features)}
    fields = list(vocabulary.actions)
    n = len(names)
    program: list[tuple[int, int, float, float]] = []
    prog_start = np.zeros(n + 1, dtype=np.int64)
    child = np.full((2, n), -1, dtype=np.int64)
    child_next = np.zeros((2, n), dtype=np.bool_)
    actions = np.full((n, len(fields)), np.nan)
    max_stack = 1
    for k, node in enumerate(rules.nodes):
        max_stack = max(max_stack, _emit(node.test, features, program))
        prog_start[k + 1] = len(program)
        for row, edge in ((0, node.no), (1, node.yes)):
            if edge is not None:
                child[row, k] = index[edge.to]
                child_next[row, k] = edge.next
        for name, operand in node.action.items():
            actions[k, fields.index(name)] = operand.value
    ops = np.array(program, dtype=np.float64).reshape(-1, 4)
    return Network(
        rules=rules, vocabulary=vocabulary, node_names=names, start=index[rules.start],
        code=np.ascontiguousarray(ops[:, 0], dtype=np.int64),
        arg=np.ascontiguousarray(ops[:, 1], dtype=np.int64),
        lo=np.ascontiguousarray(ops[:, 2]), hi=np.ascontiguousarray(ops[:, 3]),
        prog_start=prog_start, child=child, child_next=child_next, actions=actions,
        max_stack=max_stack, max_depth=_longest_chain(child, child_next))


def _longest_chain(child: np.ndarray, child_next: np.ndarray) -> int:
    """Most nodes visited in one call: longest path of immediate edges, counted in nodes.

    The loader has refused loops of immediate edges, so the memoised recursion ends.
    """
    n = child.shape[1]
    depth = np.zeros(n, dtype=np.int64)  # 0 = not computed yet
    for root in range(n):
        stack = [root]
        while stack:
            k = stack[-1]
            if depth[k]:
                stack.pop()
                continue
            pending = [int(c) for row in (0, 1) if (c := child[row, k]) >= 0
                       and not child_next[row, k] and not depth[c]]
            if pending:
                stack.extend(pending)
                continue
            below = [depth[c] for row in (0, 1) if (c := child[row, k]) >= 0
                     and not child_next[row, k]]
            depth[k] = 1 + max(below, default=0)
            stack.pop()
    return int(depth.max()) if n else 0


def loads(text: str | bytes, vocabulary: Vocabulary, path_label: str = "<string>") -> Network:
    """Check and compile rule-file text.

    Args:
        text: the YAML content.
        vocabulary: the names the file may use.
        path_label: name used in error messages; an ``extends:`` path is relative to its
            folder.

    Raises:
        ScenarioError: every problem of the file, each ``file:line: key: message``.
    """
    return compile_rules(parse(text, vocabulary, path_label), vocabulary)


def load(path: str | os.PathLike[str], vocabulary: Vocabulary) -> Network:
    """Check and compile a rule file (and the files it ``extends``).

    A process keeps the networks it compiled: the same file is parsed again only when its
    content or that of a file it extends has changed (compared by digest), so that a
    campaign's chunks do not parse the rules again and again. The arrays of a network are
    never written to.

    Raises:
        ScenarioError: unreadable file or every problem of it and of the files it extends, each
            ``file:line: key: message``.
    """
    key = (os.path.abspath(path), id(vocabulary))
    hit = _LOADED.get(key)
    if hit is not None and hit[0] is vocabulary and hit[2] == _signatures(hit[1].rules.files):
        return hit[1]
    net = compile_rules(parse_file(path, vocabulary), vocabulary)
    _LOADED[key] = (vocabulary, net, _signatures(net.rules.files))
    return net


#: networks compiled by :func:`load`: (absolute path, vocabulary id) -> (vocabulary, network,
#: signatures of the files read)
_LOADED: dict[tuple[str, int], tuple[Vocabulary, Network, tuple]] = {}


def rules_digest(files: Sequence[str]) -> str:
    """SHA-1 (hex) of the contents of a rule set's files (``RuleSet.files``), to tell later
    whether the rules a run decided by are still those on disk."""
    return hashlib.sha1(b"".join(sig or b"-" for sig in _signatures(files))).hexdigest()


def _signatures(files: Sequence[str]) -> tuple:
    """Digest of each file's content; None for one that cannot be read."""
    out = []
    for f in files:
        try:
            out.append(hashlib.sha1(Path(f).read_bytes()).digest())
        except OSError:
            out.append(None)
    return tuple(out)


# --------------------------------------------------------------------------------------------
# Evaluator
# --------------------------------------------------------------------------------------------

def evaluate(net: Network, features: np.ndarray, cursor: np.ndarray) -> Decision:
    """Run one decision step of the network for ``m`` pairs at once.

    Args:
        net: the compiled network.
        features: ``(n_features, m)`` feature values in vocabulary order (units as the vocabulary
            defines them); NaN makes every comparison on that feature false.
        cursor: ``(m,)`` integer node index where each pair starts (``net.initial_cursor(m)``
            at the first step, then the previous decision's ``cursor``).

    Returns:
        The :class:`Decision`: new cursor, merged actions, and the path of visited nodes.

    Raises:
        ValueError: wrong shapes, or a cursor that is not a node index.
    """
    feats = np.ascontiguousarray(features, dtype=np.float64)
    n_f = len(net.vocabulary.features)
    if feats.ndim != 2 or feats.shape[0] != n_f:
        raise ValueError(f"features must have shape ({n_f}, m), got {feats.shape}")
    m = feats.shape[1]
    raw = np.asarray(cursor)
    if not (np.issubdtype(raw.dtype, np.integer) or raw.size == 0):
        raise ValueError(f"cursor must hold integer node indices, got dtype {raw.dtype}")
    cur = np.ascontiguousarray(raw, dtype=np.int64)
    if cur.shape != (m,):
        raise ValueError(f"cursor must have shape ({m},), got {cur.shape}")
    if m and (cur.min() < 0 or cur.max() >= net.n_nodes):
        raise ValueError(f"cursor holds node indices outside 0..{net.n_nodes - 1}")
    new_cursor = np.empty(m, dtype=np.int64)
    actions = np.empty((net.actions.shape[1], m))
    path = np.empty((m, net.max_depth), dtype=np.int32)
    path_len = np.empty(m, dtype=np.int64)
    _evaluate(net.code, net.arg, net.lo, net.hi, net.prog_start, net.child, net.child_next,
              net.actions, net.max_stack, feats, cur, new_cursor, actions, path, path_len)
    return Decision(cursor=new_cursor, actions=actions, path=path, path_len=path_len,
                    action_fields=net.action_fields)


@kernel
def _evaluate(code: np.ndarray, arg: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              prog_start: np.ndarray, child: np.ndarray, child_next: np.ndarray,
              table: np.ndarray, max_stack: int, feats: np.ndarray, cursor: np.ndarray,
              new_cursor: np.ndarray, actions: np.ndarray, path: np.ndarray,
              path_len: np.ndarray) -> None:
    m = feats.shape[1]
    n_fields = table.shape[1]
    max_depth = path.shape[1]
    stack = np.empty(max(max_stack, 1), dtype=np.bool_)
    actions[:, :] = np.nan
    path[:, :] = -1
    for i in range(m):
        node = cursor[i]
        depth = 0
        while True:
            path[i, depth] = node
            depth += 1
            for a in range(n_fields):
                value = table[node, a]
                if value == value:  # NaN = the node does not set this field
                    actions[a, i] = value
            sp = 0
            for k in range(prog_start[node], prog_start[node + 1]):
                op = code[k]
                if op <= OP_BETWEEN:
                    x = feats[arg[k], i]
                    if x != x:
                        held = False
                    elif op == OP_LT:
                        held = x < lo[k]
                    elif op == OP_LE:
                        held = x <= lo[k]
                    elif op == OP_GT:
                        held = x > lo[k]
                    elif op == OP_GE:
                        held = x >= lo[k]
                    elif op == OP_EQ:
                        held = x == lo[k]
                    elif op == OP_NE:
                        held = x != lo[k]
                    else:
                        held = lo[k] <= x <= hi[k]
                    stack[sp] = held
                    sp += 1
                elif op == OP_TRUE:
                    stack[sp] = True
                    sp += 1
                elif op == OP_FALSE:
                    stack[sp] = False
                    sp += 1
                elif op == OP_NOT:
                    stack[sp - 1] = not stack[sp - 1]
                else:
                    count = arg[k]
                    held = op == OP_ALL
                    for j in range(sp - count, sp):
                        # all: any false item decides; any: any true item decides
                        if stack[j] != held:
                            held = not held
                            break
                    sp -= count
                    stack[sp] = held
                    sp += 1
            branch = 1 if stack[0] else 0
            nxt = child[branch, node]
            if nxt < 0:  # dead branch of a literal test: cannot be taken, stay put
                new_cursor[i] = node
                break
            if child_next[branch, node] or depth >= max_depth:
                new_cursor[i] = nxt
                break
            node = nxt
        path_len[i] = depth


# --------------------------------------------------------------------------------------------
# Explanation
# --------------------------------------------------------------------------------------------

def _holds(test: Test, values: dict[str, float]) -> bool:
    """The test on one pair's feature values (NaN comparisons false), as the kernel does."""
    if isinstance(test, Literal):
        return test.value
    if isinstance(test, Comparison):
        x = values[test.feature]
        if math.isnan(x):
            return False
        if isinstance(test.value, tuple):
            return test.value[0].value <= x <= test.value[1].value
        c = test.value.value
        return {"<": x < c, "<=": x <= c, ">": x > c, ">=": x >= c, "==": x == c,
                "!=": x != c}[test.op]
    if isinstance(test, Not):
        return not _holds(test.item, values)
    results = [_holds(item, values) for item in test.items]
    return all(results) if isinstance(test, AllOf) else any(results)


def _num(x: float) -> str:
    return "NaN" if math.isnan(x) else f"{x:.6g}"


def _named(operand: Operand, constants: Mapping[str, str]) -> str:
    """``, name = value`` for a named operand; an enum-valued parameter shows its constant."""
    if not isinstance(operand.written, str):
        return ""
    if operand.written in constants:
        return f", {operand.written} = {constants[operand.written]} ({_num(operand.value)})"
    return f", {operand.written} = {_num(operand.value)}"


def _constant(operand: Operand, enums: Mapping[str, float], constants: Mapping[str, str]
              ) -> str | None:
    """The enum constant an operand names, directly or through a parameter."""
    if not isinstance(operand.written, str):
        return None
    if operand.written in constants:
        return constants[operand.written]
    return operand.written if operand.written in enums else None


def _test_lines(test: Test, values: dict[str, float], indent: str,
                enums: Mapping[str, float], constants: Mapping[str, str]) -> list[str]:
    verdict = "true" if _holds(test, values) else "false"
    if isinstance(test, Literal):
        return [f"{indent}{verdict}"]
    if isinstance(test, Comparison):
        x = values[test.feature]
        operands = test.value if isinstance(test.value, tuple) else (test.value,)
        names = "".join(_named(o, constants) for o in operands)
        # a feature holding an enum constant the comparison names: show the constant's name
        same = [c for o in operands if (c := _constant(o, enums, constants)) is not None
                and enums[c] == x]
        if same:
            names = f" ({same[0]}){names}"
        missing = " (missing value: comparison is false)" if math.isnan(x) else ""
        return [f"{indent}{render_test(test)}: {test.feature} = {_num(x)}{names}{missing} "
                f"-> {verdict}"]
    if isinstance(test, Not):
        return [f"{indent}not -> {verdict}",
                *_test_lines(test.item, values, indent + "  ", enums, constants)]
    word = "all of" if isinstance(test, AllOf) else "any of"
    lines = [f"{indent}{word} -> {verdict}"]
    for item in test.items:
        lines += _test_lines(item, values, indent + "  ", enums, constants)
    return lines


def _action_value(operand: Operand, enums: Mapping[str, float],
                  constants: Mapping[str, str]) -> str:
    """``starboard``, ``turn_deg (30)``, ``side (port)`` or ``-5``."""
    written = operand.written
    if not isinstance(written, str) or written in enums:
        return str(written)
    shown = constants.get(written, _num(operand.value))
    return f"{written} ({shown})"


def explain(net: Network, path: Sequence[int] | np.ndarray, features: Sequence[float] |
            np.ndarray) -> str:
    """Human-readable account of one pair's decision, node by node.

    For each visited node: its name, the file and line it is written at (for a rule set that
    extends another, the parent's file for an inherited node) and its description, the test as
    written with the feature and parameter values and whether each part held, the action fields
    it set, and the child taken (now or at the next step).

    Args:
        net: the network that produced the path.
        path: one row of :attr:`Decision.path` (node indices, -1 padding ignored).
        features: ``(n_features,)`` that pair's feature values at the decision.

    Raises:
        ValueError: the feature values do not lead along ``path`` (wrong pair or step).
    """
    values = dict(zip(net.vocabulary.features, (float(v) for v in features), strict=True))
    visited = [int(k) for k in path if k >= 0]
    enums = {name: float(v) for name, v in net.vocabulary.enums.items()}
    constants = net.rules.parameter_constants
    lines: list[str] = []
    for step, k in enumerate(visited):
        node = net.rules.nodes[k]
        title = f"{step + 1}. {node.name} ({node.path}:{node.line})"
        lines.append(f"{title}: {node.description}" if node.description else title)
        held = _holds(node.test, values)
        answer = "yes" if held else "no"
        if isinstance(node.test, Literal | Comparison):
            detail = _test_lines(node.test, values, "", enums, constants)[0]
            lines.append(f"   test {detail.rsplit(' -> ', 1)[0]} -> {answer}")
        else:
            lines.append(f"   test {render_test(node.test)} -> {answer}")
            lines += _test_lines(node.test, values, "     ", enums, constants)
        if node.action:
            fields = ", ".join(f"{name} = {_action_value(o, enums, constants)}"
                               for name, o in node.action.items())
            lines.append(f"   action: {fields}")
        edge = node.yes if held else node.no
        if edge is None:
            lines.append(f"   {answer}: no child (stays at {node.name})")
            continue
        when = "next step" if edge.next else "now"
        lines.append(f"   {answer} -> {edge.to} ({when})")
        following = visited[step + 1] if step + 1 < len(visited) else None
        expected = None if edge.next else net.node_index(edge.to)
        if following != expected:
            raise ValueError("these feature values do not lead along this path (wrong pair or "
                             "decision step?)")
    return "\n".join(lines)
