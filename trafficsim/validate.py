"""``trafficsim validate``: check scenario, ship and rules files without running them.

The kind of a file is told by its top-level keys: a rules file has ``nodes`` or ``extends``
(checked against the COLREGS vocabulary, :data:`trafficsim.colregs.vocabulary.VOCABULARY`), a
ship file has ``model`` and no ``ships``, a campaign spec has ``n_encounters`` (its ship files are
checked too, and one encounter of each type it asks for is drawn); without those, the keys only
one kind of file has decide (``particulars``, ``coefficients``, ... a ship file;
``encounter_types``, ``ship_types``, ... a campaign spec), so a file that lacks its deciding key
is told so; anything else is read as a scenario (whose ship files are checked too). The rules
file a scenario or campaign names is checked with it.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from trafficsim.errors import InputError

EXIT_INVALID = 2
"""Exit code of :func:`validate_files` when a file has errors (the CLI's user-error code)."""

_RULES_KEYS = ("nodes", "extends")
# A top-level ``nodes:`` or ``extends:`` line, to recognise a rules file that is not valid YAML
_RULES_LINE = re.compile(r"^(?:nodes|extends|[\"']nodes[\"']|[\"']extends[\"'])[ \t]*:",
                         re.MULTILINE)


def is_rules_data(data: Any) -> bool:
    """True if loaded YAML data is a decision-network rules file (a mapping with ``nodes``, or
    with ``extends`` for a file that takes its nodes from another)."""
    return isinstance(data, dict) and any(key in data for key in _RULES_KEYS)


#: top-level keys only a ship file has, and only a campaign spec has (a scenario has ``ships``)
_SHIP_KEYS = frozenset({"model", "particulars", "service_speed_kn", "actuators", "coefficients",
                        "autopilot", "integration", "source"})
_CAMPAIGN_KEYS = frozenset({"n_encounters", "chunk_encounters", "policy", "encounter_types",
                            "multi_ships", "dcpa_nm", "tcpa_min", "ship_types", "speed_fraction",
                            "current_kn", "wind_mps", "rogue_fraction"})


def file_kind(data: Any) -> str:
    """``"ship"``, ``"campaign"`` or ``"scenario"``: what loaded YAML data (not a rules file) is
    read as. The deciding key (``model``, ``n_encounters``, ``ships``) wins; without one, the
    kind more of whose own keys the file has (a tie: a scenario)."""
    if not isinstance(data, dict) or "ships" in data:
        return "scenario"
    if "model" in data:
        return "ship"
    if "n_encounters" in data:
        return "campaign"
    keys = set(data)
    ship, campaign = len(keys & _SHIP_KEYS), len(keys & _CAMPAIGN_KEYS)
    if ship > campaign:
        return "ship"
    return "campaign" if campaign > ship else "scenario"


def _looks_like_rules(path: Path) -> bool:
    try:
        text = path.read_bytes()[:1_000_000].decode("utf-8", "replace")
    except OSError:
        return False
    return _RULES_LINE.search(text) is not None


def _errors(err: InputError) -> list[InputError]:
    from trafficsim.io.yamlio import locate

    return [locate(e) for e in getattr(err, "errors", None) or [err]]


def _check_rules(path: Path) -> tuple[list[InputError], str]:
    from trafficsim.colregs.rulefile import parse_file
    from trafficsim.colregs.vocabulary import VOCABULARY

    try:
        rules = parse_file(path, VOCABULARY)
    except InputError as err:
        return _errors(err), ""
    n = len(rules.nodes)
    return [], f"ok ({n} node{'' if n == 1 else 's'})"


def _check_ship(path: Path) -> None:
    """Load a ship file and build its model family (the family's own checks of its values)."""
    from trafficsim.ships.base import families
    from trafficsim.ships.library import load_ship

    spec = load_ship(str(path))
    families()[spec["model"]].build([spec])


def check_file(path: Path) -> tuple[list[InputError], str]:
    """Check one file.

    Returns:
        ``(errors, summary)``: every error found (located, sorted as the loaders sort them),
        and, when there is none, what to print after the file name: ``"ok"``, or ``"ok (N
        nodes)"`` for a rules file (N counts the nodes it inherits).
    """
    from trafficsim.io.yamlio import load_yaml

    if path.is_dir():  # a ship's MMG parameter folder
        from trafficsim.diagnose.mmgfolder import FILES

        if not any((path / name).exists() for name in FILES):
            return [InputError("is a directory, expected a YAML file or an MMG parameter "
                               f"folder (holding {', '.join(FILES)})", path=str(path))], ""
        try:
            _check_ship(path.resolve())
        except InputError as err:
            return _errors(err), ""
        return [], "ok"
    if path.exists() and not path.is_file():  # a pipe or a device: it reads only once
        return [InputError("is not a regular file (a pipe or a device): validate reads a file "
                           "more than once and looks for the files it names beside it; save "
                           "it to a file first", path=str(path))], ""
    try:
        doc = load_yaml(path)
    except InputError as err:
        if _looks_like_rules(path):
            # the rules reader adds hints for unquoted operators ("!=", ">")
            return _check_rules(path)
        return _errors(err), ""
    if is_rules_data(doc.data):
        return _check_rules(path)
    rules = None
    try:
        kind = file_kind(doc.data)
        if kind == "ship":
            _check_ship(path.resolve())
        elif kind == "campaign":
            from trafficsim.campaign.generator import spec_errors
            from trafficsim.campaign.spec import load_spec

            spec = load_spec(path)
            found = spec_errors(spec)  # its ship files, and a type no draw can place
            if found:
                return [e for err in found for e in _errors(err)], ""
            rules = spec.rules
        else:
            from trafficsim.io.scenario import load_scenario

            scenario = load_scenario(path)
            for ship_file in scenario.ship_files:
                _check_ship(ship_file)
            rules = scenario.rules
    except InputError as err:
        return _errors(err), ""
    if rules is not None:  # the rules file it names, checked as a run would read it
        errors = _check_rules(path.parent / rules)[0]
        if errors:
            return errors, ""
    return [], "ok"


def validate_file(path: Path) -> list[InputError]:
    """All errors found in ``path`` (a scenario, ship, rules or campaign file, told apart by its
    keys)."""
    return check_file(path)[0]


def validate_files(paths: Sequence[Path], out: TextIO | None = None,
                   err: TextIO | None = None) -> int:
    """Check files and report as ``trafficsim validate`` does.

    Prints ``FILE: ok`` (``FILE: ok (N nodes)`` for a rules file) on ``out`` for a good file,
    and one ``trafficsim: error: file:line: key: message`` line per error on ``err``.

    Returns:
        0 if every file is valid, else :data:`EXIT_INVALID`.
    """
    out = sys.stdout if out is None else out
    err = sys.stderr if err is None else err
    bad = 0
    for path in paths:
        errors, summary = check_file(path)
        for error in errors:
            print(f"trafficsim: error: {error}", file=err)
        if errors:
            bad += 1
        else:
            print(f"{path}: {summary}", file=out)
    return EXIT_INVALID if bad else 0
