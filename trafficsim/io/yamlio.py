"""Safe YAML loading that keeps line numbers, and schema validation with located errors.

Every problem a user can put into a YAML file ends as a :class:`~trafficsim.errors.ScenarioError`
whose text reads ``file:line: key: message`` and says what was expected.

Loading (:func:`load_yaml`, :func:`parse_yaml`) has ``yaml.safe_load`` semantics (``SafeLoader``
only; no Python objects are ever built) and is stricter where plain PyYAML surprises users:

* duplicate keys are an error (PyYAML silently keeps the last one);
* anchors and aliases are refused, so a "billion laughs" file cannot expand;
* files over :data:`MAX_BYTES`, non-UTF-8 files, empty files, a top level that is not a mapping,
  keys that are not text, merge keys (``<<``) and tags other than the plain JSON-like ones are
  errors;
* YAML 1.1 number forms that nobody writes on purpose are kept as *text*, so that a schema
  expecting a number rejects them with a hint instead of taking a silently wrong value:
  base-60 ``1:30`` (PyYAML: 90) and leading-zero octal ``010`` (PyYAML: 8); timestamps stay text;
* as *values*, the words ``yes/no/on/off`` still load as booleans (``safe_load`` semantics),
  and a schema expecting text reports them with a hint to quote them; as mapping *keys*, plain
  words that YAML 1.1 would read as booleans or null (``yes:``, ``no:``, ``on:``, ``off:``,
  ``true:``, ``null:``, ``~:`` ...) are text, since keys must be text anyway (an empty key, a
  number or an explicitly tagged key such as ``!!bool yes:`` is still refused);
* any exception raised by the YAML library becomes a located error.

Validation (:func:`validate`, :func:`validate_document`) runs a pydantic v2 model over the data
and turns every pydantic error into a :class:`ScenarioError` located with :meth:`Document.line_of`
and phrased in plain words ("expected a number, got 'fast'", "unknown key 'sped_kn' (did you
mean 'speed_kn'?)", "missing required key 'name'"). The exception raised carries the first error
(by line) in its message and all of them in its ``errors`` attribute.
"""

from __future__ import annotations

import difflib
import math
import numbers
import os
import re
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, NoReturn, TypeVar

import pydantic
import yaml
from pydantic import AfterValidator, BaseModel, ConfigDict, model_validator
from pydantic.types import AllowInfNan
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from trafficsim.errors import InputError, ScenarioError

__all__ = [
    "MAX_BYTES",
    "MAX_DEPTH",
    "Document",
    "FieldError",
    "Integer",
    "Loc",
    "Number",
    "Strict",
    "Text",
    "collect_errors",
    "finite_number",
    "format_loc",
    "load_yaml",
    "number_hint",
    "parse_yaml",
    "raise_errors",
    "validate",
    "validate_document",
]

MAX_BYTES = 1_000_000
"""Default cap on the size of a YAML file, in bytes."""

MAX_DEPTH = 64
"""Deepest nesting of mappings and lists accepted (deeper input is refused before it recurses)."""

Loc = tuple[str | int, ...]
"""A path into a document: mapping keys (str) and list indices (int): ``("ships", 1, "name")``."""

ModelT = TypeVar("ModelT", bound=BaseModel)

_TAG = "tag:yaml.org,2002:"
_STR, _INT, _FLOAT, _BOOL, _NULL = (_TAG + t for t in ("str", "int", "float", "bool", "null"))
_MAP, _SEQ, _MERGE, _TIMESTAMP, _VALUE = (
    _TAG + t for t in ("map", "seq", "merge", "timestamp", "value"))
_TRUE_WORDS = frozenset({"true", "yes", "on"})
_FALSE_WORDS = frozenset({"false", "no", "off"})
_LEADING_ZERO = re.compile(r"[-+]?0[0-9_]+")
# Written like a float in YAML 1.2 / JSON but read as text by YAML 1.1 ("1e5", "1.5e3").
_EXPONENT_TEXT = re.compile(r"([-+]?)([0-9]+)(?:\.([0-9]*))?[eE]([-+]?)([0-9]+)")
_SURROGATE = re.compile("[\ud800-\udfff]")


# --------------------------------------------------------------------------------------------
# Schema building blocks
# --------------------------------------------------------------------------------------------

def _not_blank(value: str) -> str:
    if not value.strip():
        raise ValueError("must not be empty")
    return value


Number = Annotated[float, pydantic.Strict(), AllowInfNan(False)]
"""A finite number; accepts YAML ints and floats, rejects booleans and text (even "12")."""

Integer = Annotated[int, pydantic.Strict()]
"""A whole number; rejects booleans, floats and text."""

Text = Annotated[str, AfterValidator(_not_blank)]
"""Non-blank text; YAML booleans and numbers are rejected with a hint to quote them."""


def _candidates(annotation: Any) -> list[Any]:
    """The member types of an annotation, with Annotated and unions unwrapped."""
    origin = typing.get_origin(annotation)
    if origin is Annotated:
        return _candidates(typing.get_args(annotation)[0])
    if origin is typing.Union or origin is types.UnionType:
        return [c for arg in typing.get_args(annotation) for c in _candidates(arg)]
    return [annotation]


class _Rejected:
    """Stands in for a bool or text given where only a number fits, so that pydantic's own
    number check fails on it (reporting it along with every other error of the model)."""

    __slots__ = ("value",)

    def __init__(self, value: Any) -> None:
        self.value = value

    def __repr__(self) -> str:
        return repr(self.value)


def _numeric_only(annotation: Any) -> bool:
    """True if the annotation accepts numbers (and maybe None) but no bool or text."""
    members = [tp for tp in _candidates(annotation) if tp is not type(None)]
    return bool(members) and all(tp is float or tp is int for tp in members)


def _screen(annotation: Any, value: Any) -> Any:
    """``value`` with every bool or text that sits where only a number fits replaced by a
    :class:`_Rejected` (pydantic's lax mode would read ``true`` as 1 and ``"12"`` as 12)."""
    if _numeric_only(annotation):
        return _Rejected(value) if isinstance(value, bool | str) else value
    for tp in _candidates(annotation):
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if isinstance(value, list) and args:
            if origin is tuple:
                items = [args[0]] * len(value) if args[-1] is Ellipsis else list(args)
            elif origin in (list, Sequence, set, frozenset):
                items = [args[0]] * len(value)
            else:
                continue
            return [_screen(items[i], v) if i < len(items) else v for i, v in enumerate(value)]
        if isinstance(value, dict) and origin in (dict, Mapping) and len(args) == 2:
            return {k: _screen(args[1], v) for k, v in value.items()}
    return value


class Strict(BaseModel):
    """Base class of every file schema: unknown keys, NaN and infinity are errors; frozen.

    Numbers never accept booleans or text: a before-validator screens every field whose type
    is only numeric (``float``, ``int``, ``float | None``, ``list[float]``, ``dict[str, float]``
    ...), so plain ``float`` annotations are as strict as :data:`Number`.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=False, frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _numbers_are_numbers(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        screened = dict(data)
        for name, info in cls.model_fields.items():
            key = info.alias or name
            if key in screened:
                screened[key] = _screen(info.annotation, screened[key])
        return screened


class FieldError(ValueError):
    """A ValueError raised in a validator, located deeper than the field that raised it.

    pydantic locates a validator's error at its field; raise ``FieldError(msg, loc=(1, "name"))``
    from the validator of ``ships`` to point at ``ships[1].name`` instead.
    """

    def __init__(self, message: str, loc: Loc = ()) -> None:
        super().__init__(message)
        self.loc = tuple(loc)


# --------------------------------------------------------------------------------------------
# Document
# --------------------------------------------------------------------------------------------

def format_loc(loc: Sequence[str | int]) -> str:
    """Dotted key of a location: ``("ships", 1, "speed_kn")`` -> ``"ships[1].speed_kn"``; an
    empty key is quoted in brackets (``types['']``), and the validator's ``[key]`` marker (the
    mapping key itself is wrong) is appended as it is."""
    out = ""
    for part in loc:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        elif part == "[key]" or (out and part == ""):
            out += part if part == "[key]" else f"[{str(part)!r}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def parse_loc(key: str) -> tuple[str | int, ...]:
    """The location of a dotted key (the inverse of :func:`format_loc` for plain keys):
    ``"ships[1].speed_kn"`` -> ``("ships", 1, "speed_kn")``."""
    out: list[str | int] = []
    for part in key.split("."):
        name, *indices = part.split("[")
        if name:
            out.append(name)
        out += [int(i.rstrip("]")) for i in indices if i.rstrip("]").isdigit()]
    return tuple(out)


def locate(err: InputError) -> InputError:
    """``err`` with its line filled in from its YAML file and key where it names both but no
    line (errors raised after a file was read, e.g. by a model family's own checks); as it is
    where the file or the key cannot be found."""
    if err.line is not None or not err.path or not err.key:
        return err
    try:
        doc = load_yaml(err.path)
    except (InputError, OSError):
        return err
    err.line = doc.line_of(parse_loc(err.key))
    err.args = (err.render(),)
    return err


def _line(node: Node) -> int:
    return node.start_mark.line + 1


@dataclass(frozen=True)
class Document:
    """A loaded YAML file: plain data plus the node tree that remembers lines.

    Attributes:
        path: the file name as given by the caller (used in messages).
        data: the top-level mapping as plain dicts, lists and scalars.
        root: the composed ``yaml.MappingNode`` of the top level.
    """

    path: str
    data: dict[str, Any]
    root: MappingNode

    def _walk(self, loc: Sequence[str | int]) -> tuple[Node, int, bool]:
        """Deepest node on ``loc``, its line, and whether the whole path exists."""
        node: Node = self.root
        line = _line(node)
        for part in loc:
            if isinstance(node, MappingNode) and isinstance(part, str):
                for key, value in node.value:
                    if isinstance(key, ScalarNode) and key.value == part:
                        # An entry is located at its key: for a block value the key is the
                        # header line the user looks for.
                        node, line = value, _line(key)
                        break
                else:
                    return node, line, False
            elif (isinstance(node, SequenceNode) and isinstance(part, int)
                  and not isinstance(part, bool) and 0 <= part < len(node.value)):
                node = node.value[part]
                line = _line(node)
            else:
                return node, line, False
        return node, line, True

    def line_of(self, loc: Sequence[str | int]) -> int:
        """1-based line of the deepest existing node on ``loc``.

        A mapping entry is located at its key; a list item at its first character; a missing key
        at its parent (the entry or item that should hold it).
        """
        return self._walk(loc)[1]

    def node_at(self, loc: Sequence[str | int]) -> Node | None:
        """The value node at ``loc``, or None if the path does not exist."""
        node, _, found = self._walk(loc)
        return node if found else None

    def error(self, message: str, loc: Sequence[str | int] = ()) -> ScenarioError:
        """A :class:`ScenarioError` about ``loc`` in this file (returned, not raised)."""
        return ScenarioError(message, path=self.path, line=self.line_of(loc),
                             key=format_loc(loc) or None)


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------

class _Refused(yaml.composer.ComposerError):
    """Valid YAML that this loader refuses on purpose (anchors, aliases, deep nesting)."""


class _Loader(yaml.SafeLoader):
    """SafeLoader whose composer refuses anchors and aliases and bounds the nesting depth."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            raise _Refused(None, None,
                           f"aliases ('*{event.anchor}') are not allowed; write the value out "
                           "in full (anchors and aliases are refused so that a file cannot "
                           "expand exponentially)", event.start_mark)
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            raise _Refused(None, None,
                           f"anchors ('&{anchor}') are not allowed; write each value out in "
                           "full", event.start_mark)
        nests = isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent))
        self._depth += nests  # (a scalar is a value inside a level, not a level)
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(None, None, f"nesting is deeper than {MAX_DEPTH} levels",
                               event.start_mark)
            node = super().compose_node(parent, index)
        finally:
            self._depth -= nests
        # The composer asks for a mapping key with index None (a value's index is its key).
        # A plain, untagged key that YAML 1.1 resolves to a boolean or null is meant as text:
        # ``yes:`` and ``no:`` are words, not true and false.
        if (isinstance(parent, MappingNode) and index is None
                and isinstance(event, yaml.ScalarEvent) and event.tag is None
                and event.style is None and node.tag in (_BOOL, _NULL) and node.value):
            node.tag = _STR
        return node


def _unsupported(tag: str) -> str:
    short = "!!" + tag.removeprefix(_TAG) if tag.startswith(_TAG) else tag
    return (f"unsupported tag '{_clip(short)}'; only plain values, lists and mappings are "
            "allowed")


def _construct_scalar(node: ScalarNode, path: str, loc: Loc) -> Any:
    tag, text = node.tag, node.value

    def fail(message: str) -> NoReturn:
        raise ScenarioError(message, path=path, line=_line(node), key=format_loc(loc) or None)

    if tag in (_STR, _TIMESTAMP, _VALUE, _MERGE):
        # Timestamps, '=' and a '<<' value stay text: no schema here wants a datetime.
        if _SURROGATE.search(text):
            fail("text contains an invalid character (a lone UTF-16 surrogate escape)")
        return text
    if tag == _NULL:
        if text not in ("", "~") and text.lower() != "null":
            fail(f"'{_clip(text)}' is not a valid null")
        return None
    if tag == _BOOL:
        word = text.lower()
        if word in _TRUE_WORDS:
            return True
        if word in _FALSE_WORDS:
            return False
        fail(f"'{_clip(text)}' is not a boolean; write true or false")
    if tag in (_INT, _FLOAT):
        digits = text.replace("_", "")
        if ":" in digits or (tag == _INT and _LEADING_ZERO.fullmatch(digits)):
            # Base-60 and leading-zero octal: keep the text so a number field rejects it.
            return text
        try:
            if tag == _INT:
                return int(digits, 0)
            lowered = digits.lower()
            if lowered in (".inf", "+.inf"):
                return float("inf")
            if lowered == "-.inf":
                return float("-inf")
            if lowered == ".nan":
                return float("nan")
            return float(digits)
        except ValueError:
            kind = "a whole number" if tag == _INT else "a number"
            fail(f"'{_clip(text)}' is not {kind}")
    fail(_unsupported(tag))


def _describe_key_node(node: Node) -> str:
    if isinstance(node, MappingNode):
        return "a mapping"
    if isinstance(node, SequenceNode):
        return "a list"
    if node.tag == _NULL and node.value == "":
        return "an empty key"
    return f"'{_clip(node.value)}'"


def _construct(node: Node, path: str, loc: Loc) -> Any:
    """Plain Python data from a composed node; duplicate and non-text keys are errors."""
    if isinstance(node, ScalarNode):
        return _construct_scalar(node, path, loc)
    where = format_loc(loc) or None
    if isinstance(node, SequenceNode):
        if node.tag != _SEQ:
            raise ScenarioError(_unsupported(node.tag), path=path, line=_line(node), key=where)
        return [_construct(item, path, (*loc, i)) for i, item in enumerate(node.value)]
    if not isinstance(node, MappingNode) or node.tag != _MAP:
        raise ScenarioError(_unsupported(node.tag), path=path, line=_line(node), key=where)
    out: dict[str, Any] = {}
    first_line: dict[str, int] = {}
    for key_node, value_node in node.value:
        line = _line(key_node)
        if isinstance(key_node, ScalarNode) and key_node.tag == _MERGE:
            raise ScenarioError("merge keys ('<<') are not supported; write the keys out in full",
                                path=path, line=line, key=where)
        if not (isinstance(key_node, ScalarNode) and key_node.tag == _STR):
            hint = (" (put it in quotes)" if isinstance(key_node, ScalarNode) and key_node.value
                    else "")
            raise ScenarioError(f"keys must be text, got {_describe_key_node(key_node)}{hint}",
                                path=path, line=line, key=where)
        key = key_node.value
        if _SURROGATE.search(key):
            raise ScenarioError("key contains an invalid character (a lone surrogate escape)",
                                path=path, line=line, key=where)
        if key in out:
            raise ScenarioError(
                f"duplicate key '{_clip(key)}' (first at line {first_line[key]}, again at line "
                f"{line}); keep only one", path=path, line=line, key=format_loc((*loc, key)))
        first_line[key] = line
        out[key] = _construct(value_node, path, (*loc, key))
    return out


def _line_at(text: str, index: int) -> int:
    return text.count("\n", 0, max(index, 0)) + 1


def _yaml_error(exc: yaml.YAMLError, text: str, path: str) -> ScenarioError:
    """A located ScenarioError from any error of the YAML library."""
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        problem = exc.problem or exc.context or "invalid YAML"
        if isinstance(exc, _Refused):
            return ScenarioError(problem, path=path, line=line)
        if problem == "but found another document":
            return ScenarioError("a second YAML document starts here ('---'); a file holds "
                                 "one document", path=path, line=line)
        message = f"invalid YAML: {problem}"
        if exc.context and exc.problem:
            cmark = exc.context_mark
            if cmark is not None and (line is None or cmark.line + 1 != line):
                message += f" ({exc.context} started at line {cmark.line + 1})"
            else:
                message += f" ({exc.context})"
        if "'\\t'" in problem:
            message += "; tabs cannot indent YAML, use spaces"
        closers = {"flow sequence": "']'", "flow mapping": "'}'", "quoted scalar": "quote"}
        for what, closer in closers.items():
            if exc.context and what in exc.context:
                message += f"; is a closing {closer} missing?"
        return ScenarioError(message, path=path, line=line)
    if isinstance(exc, yaml.reader.ReaderError):
        char = exc.character  # PyYAML gives the code point as an int
        code = f"U+{ord(char) if isinstance(char, str) else char:04X}"
        return ScenarioError(f"invalid character {code}: control characters are not allowed "
                             "in YAML", path=path, line=_line_at(text, exc.position))
    return ScenarioError(f"invalid YAML: {exc}", path=path)


def _decode(data: bytes, path: str) -> str:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ScenarioError(f"file is not UTF-8 text (byte 0x{data[exc.start]:02X}); save it "
                            "as UTF-8", path=path, line=line) from None
    return text.removeprefix("\ufeff")


def parse_yaml(source: str | bytes, path: str = "<string>", *,
               max_bytes: int = MAX_BYTES) -> Document:
    """Parse YAML text (or UTF-8 bytes) into a :class:`Document`.

    Args:
        source: the file content.
        path: name used in error messages.
        max_bytes: size cap; larger input is refused.

    Raises:
        ScenarioError: for any problem, located at a line when one is known.
    """
    data = source if isinstance(source, bytes) else source.encode("utf-8", "surrogatepass")
    if len(data) > max_bytes:
        raise ScenarioError(f"file is larger than the limit of {max_bytes} bytes", path=path)
    text = _decode(data, path)
    if not text.strip():
        raise ScenarioError("file is empty; expected a mapping of 'key: value' lines",
                            path=path, line=1)
    try:
        root = yaml.compose(text, Loader=_Loader)
        if root is None:
            raise ScenarioError("file is empty (only comments); expected a mapping of "
                                "'key: value' lines", path=path, line=1)
        if not isinstance(root, MappingNode):
            got = "a list" if isinstance(root, SequenceNode) else f"'{_clip(root.value)}'"
            raise ScenarioError(f"the top level must be a mapping of 'key: value' lines, got "
                                f"{got}", path=path, line=_line(root))
        content = _construct(root, path, ())
    except ScenarioError:
        raise
    except yaml.YAMLError as exc:
        raise _yaml_error(exc, text, path) from None
    except RecursionError:
        raise ScenarioError("nesting is too deep", path=path) from None
    except Exception as exc:  # PyYAML leaks ValueError, AttributeError, TypeError, ...
        raise ScenarioError(f"cannot read YAML ({type(exc).__name__}: {exc})",
                            path=path) from None
    return Document(path=path, data=content, root=root)


def load_yaml(path: str | os.PathLike[str], *, max_bytes: int = MAX_BYTES) -> Document:
    """Load a YAML file into a :class:`Document` (see the module docstring for the rules).

    Args:
        path: the file.
        max_bytes: size cap in bytes (default 1 MB).

    Raises:
        ScenarioError: unreadable, oversize, non-UTF-8, empty or invalid file.
    """
    name = os.fspath(path)
    return parse_yaml(read_file(name, max_bytes), name, max_bytes=max_bytes)


def read_bytes(name: str, max_bytes: int = MAX_BYTES) -> bytes:
    """At most ``max_bytes`` + 1 bytes of a file (one more, so that the reader refuses a larger
    file); OS errors propagate."""
    with open(name, "rb") as handle:
        return handle.read(max_bytes + 1)


def read_file(path: str | os.PathLike[str], max_bytes: int = MAX_BYTES,
              kind: str = "a YAML file") -> bytes:
    """:func:`read_bytes` with OS errors as located :class:`ScenarioError` (``kind`` names
    what a directory should have been)."""
    name = os.fspath(path)
    try:
        return read_bytes(name, max_bytes)
    except FileNotFoundError:
        raise ScenarioError("file not found", path=name) from None
    except IsADirectoryError:
        raise ScenarioError(f"is a directory, expected {kind}", path=name) from None
    except OSError as exc:
        raise ScenarioError(f"cannot read file ({exc.strerror or exc})", path=name) from None


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------

def _clip(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt(value: Any) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return str(value)


def finite_number(value: Any) -> float | None:
    """``value`` as a finite float; None for booleans, text and other non-numbers, NaN,
    infinity and integers beyond the float range (which ``float`` refuses with OverflowError)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def shown(value: Any, node: Node | None = None) -> str:
    """How the offending value looks in the file (from its YAML ``node`` where known)."""
    if isinstance(value, _Rejected):
        value = value.value
    if isinstance(node, ScalarNode):
        if node.style is None and node.tag == _NULL and node.value in ("", "~"):
            return "nothing (an empty value)"
        if node.style is None and (node.tag in (_INT, _FLOAT, _NULL)
                                   or node.value in ("true", "false")):
            return _clip(node.value)
        return f"'{_clip(node.value)}'"
    if isinstance(node, MappingNode):
        return "a mapping"
    if isinstance(node, SequenceNode):
        return "a list"
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "nothing (an empty value)"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list | tuple):
        return "a list"
    if isinstance(value, str):
        return f"'{_clip(value)}'"
    return _clip(repr(value))


def _sexagesimal(digits: str) -> str:
    """The value YAML 1.1 gives a base-60 scalar such as ``1:30`` (90) or ``-1:02:03.5``."""
    sign = -1.0 if digits.startswith("-") else 1.0
    value = 0.0
    for part in digits.lstrip("+-").split(":"):
        value = value * 60.0 + float(part or 0)
    return _fmt(sign * value)


def number_hint(node: Node | None) -> str:
    """Why a plain scalar that looks numeric was not read as a number."""
    if not isinstance(node, ScalarNode):
        return ""
    text = node.value
    if node.style is not None:
        try:
            float(text)
        except ValueError:
            return ""
        return " (remove the quotes)"
    digits = text.replace("_", "")
    if node.tag in (_INT, _FLOAT) and ":" in digits:
        return (f" (YAML 1.1 would read this as the base-60 number {_sexagesimal(digits)}; "
                "write the number you mean in plain units)")
    if node.tag in (_INT, _STR) and _LEADING_ZERO.fullmatch(digits):
        return (f" (YAML 1.1 would read this as the octal number {int(digits, 8)}; write it "
                "without the leading zero)" if re.fullmatch(r"[-+]?0[0-7]+", digits) else
                " (write it without the leading zero)")
    match = _EXPONENT_TEXT.fullmatch(digits)
    if node.tag == _STR and match:
        sign, whole, frac, esign, exp = match.groups()
        fixed = f"{sign}{whole}.{frac or '0'}e{esign or '+'}{exp}"
        return f" (YAML 1.1 reads this as text; write {fixed})"
    if node.tag == _BOOL and text.lower() not in ("true", "false"):
        return " (YAML reads this word as a boolean)"
    return ""


def _text_hint(node: Node | None) -> str:
    """Hint for a plain scalar YAML typed as something other than text."""
    if (isinstance(node, ScalarNode) and node.style is None
            and node.tag in (_BOOL, _INT, _FLOAT, _NULL) and node.value not in ("", "~")):
        kind = {_BOOL: "a boolean", _INT: "a number", _FLOAT: "a number", _NULL: "empty"}
        return (f" (YAML reads it as {kind[node.tag]}; put it in quotes if you mean text: "
                f"\"{_clip(node.value)}\")")
    return ""


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _step(annotation: Any, part: str | int) -> Any:
    for tp in _candidates(annotation):
        if isinstance(part, str) and _is_model(tp) and part in tp.model_fields:
            return tp.model_fields[part].annotation
        if isinstance(part, int):
            origin, args = typing.get_origin(tp), typing.get_args(tp)
            if origin is tuple and args:
                if len(args) == 2 and args[1] is Ellipsis:
                    return args[0]
                if part < len(args):
                    return args[part]
            elif origin in (list, Sequence, set, frozenset) and args:
                return args[0]
    return None


def _field_names(model_cls: type[BaseModel], loc: Loc) -> list[str]:
    """Keys allowed in the mapping at ``loc`` (empty if not a model)."""
    annotation: Any = model_cls
    for part in loc:
        annotation = _step(annotation, part)
        if annotation is None:
            return []
    for tp in _candidates(annotation):
        if _is_model(tp):
            return [info.alias or name for name, info in tp.model_fields.items()]
    return []


def _suggestion(model_cls: type[BaseModel], loc: Loc) -> str | None:
    """The allowed key closest to the unknown key at ``loc``, if any is close."""
    allowed = _field_names(model_cls, loc[:-1])
    close = difflib.get_close_matches(str(loc[-1]), allowed, n=1, cutoff=0.6)
    return close[0] if close else None


def _message(err: Mapping[str, Any], loc: Loc, node: Node | None,
             model_cls: type[BaseModel]) -> str:
    """Plain-words message for one pydantic error."""
    kind = err["type"]
    ctx = err.get("ctx") or {}
    value = err.get("input")
    got = shown(value, node)
    if kind == "missing":
        if loc and isinstance(loc[-1], int):  # a position of a list, not a key
            return f"missing list item {loc[-1] + 1} (the list has too few items)"
        return f"missing required key '{loc[-1]}'" if loc else "missing value"
    if kind == "extra_forbidden":
        key = str(loc[-1])
        close = _suggestion(model_cls, loc)
        if close:
            return f"unknown key '{_clip(key)}' (did you mean '{close}'?)"
        allowed = _field_names(model_cls, loc[:-1])
        listing = f"; allowed keys: {', '.join(allowed)}" if allowed else ""
        return f"unknown key '{_clip(key)}'{listing}"
    if kind in ("float_type", "float_parsing"):
        return f"expected a number, got {got}{number_hint(node)}"
    if kind in ("int_type", "int_parsing", "int_from_float", "int_parsing_size"):
        return f"expected a whole number, got {got}{number_hint(node)}"
    if kind == "finite_number":
        return f"expected a finite number, got {got}"
    if kind in ("bool_type", "bool_parsing"):
        return f"expected true or false, got {got}"
    if kind in ("string_type", "string_unicode"):
        return f"expected text, got {got}{_text_hint(node)}"
    if kind == "string_too_short":
        if ctx.get("min_length") == 1:
            return "must not be empty"
        return f"expected at least {ctx.get('min_length')} characters, got {got}"
    if kind == "string_too_long":
        return f"expected at most {ctx.get('max_length')} characters"
    if kind == "string_pattern_mismatch":
        return f"expected text matching {ctx.get('pattern')}, got {got}"
    comparisons = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="),
                   "less_than": ("lt", "<"), "less_than_equal": ("le", "<=")}
    if kind in comparisons:
        name, symbol = comparisons[kind]
        return f"must be {symbol} {_fmt(ctx.get(name))}, got {got}"
    if kind == "multiple_of":
        return f"must be a multiple of {_fmt(ctx.get('multiple_of'))}, got {got}"
    if kind in ("list_type", "tuple_type", "set_type", "frozen_set_type", "iterable_type"):
        return f"expected a list, got {got}"
    if kind in ("dict_type", "model_type", "model_attributes_type", "dataclass_type"):
        return f"expected a mapping of 'key: value' lines, got {got}"
    if kind in ("too_short", "too_long"):
        bound = "at least" if kind == "too_short" else "at most"
        limit = ctx.get("min_length" if kind == "too_short" else "max_length")
        noun = "item" if limit == 1 else "items"
        return f"expected {bound} {limit} {noun}, got {ctx.get('actual_length')}"
    if kind == "literal_error":
        return f"expected {ctx.get('expected')}, got {got}"
    if kind == "enum":
        return f"expected one of {ctx.get('expected')}, got {got}"
    if kind == "none_required":
        return f"expected an empty value, got {got}"
    if kind == "value_error" and isinstance(ctx.get("error"), BaseException):
        return str(ctx["error"])
    if kind == "assertion_error":
        return str(err["msg"]).removeprefix("Assertion failed, ")
    return str(err["msg"])  # custom errors (PydanticCustomError) carry their own words


def _to_error(doc: Document, model_cls: type[BaseModel], err: Mapping[str, Any]) -> ScenarioError:
    loc: Loc = tuple(err["loc"])
    ctx = err.get("ctx") or {}
    if err["type"] == "value_error" and isinstance(ctx.get("error"), FieldError):
        loc = (*loc, *ctx["error"].loc)
    node = doc.node_at(loc)
    return ScenarioError(_message(err, loc, node, model_cls), path=doc.path,
                         line=doc.line_of(loc), key=format_loc(loc) or None)


def collect_errors(doc: Document, model_cls: type[ModelT],
                   context: dict[str, Any] | None = None
                   ) -> tuple[ModelT | None, list[ScenarioError]]:
    """Validate ``doc.data`` with ``model_cls``; return ``(instance, [])`` or ``(None, errors)``.

    Use this when more checks (e.g. ship lookups) should be reported together with the schema
    errors; then call :func:`raise_errors` on the combined list.
    """
    try:
        return model_cls.model_validate(doc.data, context=context), []
    except pydantic.ValidationError as exc:
        errs = exc.errors()
    # A misspelt key also makes the key it was meant to be "missing": report the typo only.
    meant = {(*err["loc"][:-1], _suggestion(model_cls, tuple(err["loc"])))
             for err in errs if err["type"] == "extra_forbidden"}
    return None, [_to_error(doc, model_cls, err) for err in errs
                  if not (err["type"] == "missing" and tuple(err["loc"]) in meant)]


def raise_errors(errors: Sequence[ScenarioError]) -> NoReturn:
    """Raise one ScenarioError for a non-empty list of errors.

    The message is the first error by line (plus "(and N more errors)"); the attribute
    ``errors`` holds all of them sorted by line, for ``trafficsim validate`` to print.
    """
    if not errors:
        raise ValueError("raise_errors needs at least one error")
    ordered = sorted(errors, key=lambda e: e.line if e.line is not None else 0)
    first = ordered[0]
    more = len(ordered) - 1
    suffix = f" (and {more} more error{'s' if more > 1 else ''})" if more else ""
    exc = ScenarioError(first.message + suffix, path=first.path, line=first.line, key=first.key)
    exc.errors = list(ordered)
    raise exc


def validate_document(doc: Document, model_cls: type[ModelT],
                      context: dict[str, Any] | None = None) -> ModelT:
    """Validate a loaded document with a pydantic model, raising located errors.

    Raises:
        ScenarioError: the first error by line; all errors in its ``errors`` attribute.
    """
    instance, errors = collect_errors(doc, model_cls, context)
    if errors:
        raise_errors(errors)
    assert instance is not None
    return instance


def validate(path: str | os.PathLike[str], model_cls: type[ModelT],
             context: dict[str, Any] | None = None) -> ModelT:
    """Load ``path`` with :func:`load_yaml` and validate it with ``model_cls``.

    Args:
        path: the YAML file.
        model_cls: a pydantic model (normally a :class:`Strict` subclass).
        context: passed to ``model_validate`` for validators that need it.

    Raises:
        ScenarioError: located; all schema errors in its ``errors`` attribute.
    """
    return validate_document(load_yaml(path), model_cls, context)
