"""Writing an identified ship as a ship file (the schema of ``trafficsim/ships/library/*.yaml``).

The file is written as plain YAML text (atomically), with the fitted coefficients marked and
their nominal 95 % intervals as comments, once the ship-library loader has accepted the text
(checked on a scratch copy), so a file that the loader would reject is never written nor
reported as a result.
"""

from __future__ import annotations

import json
import math
import re
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from trafficsim.errors import ShipLibraryError
from trafficsim.io.results import atomic_write

_PARTS_ORDER = ("length_m", "beam_m", "draught_m")


def number(value: float) -> str:
    """A float as a YAML 1.1 float literal (PyYAML reads ``1e-05`` as a string)."""
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"not a finite number: {value}")
    text = f"{v:.10g}"
    mantissa, _, exponent = text.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return mantissa + ("e" + exponent if exponent else "")


#: characters YAML does not take literally inside a double-quoted scalar (DEL and the C1
#: controls are refused, NEL and the Unicode line and paragraph separators fold to a space,
#: a byte-order mark is dropped): written as escapes
_YAML_ESCAPE = re.compile("[\x7f-\x9f\u2028\u2029\ufeff]")


def text(value: str) -> str:
    """A string as a YAML double-quoted scalar (JSON escapes are valid YAML escapes)."""
    return _YAML_ESCAPE.sub(lambda m: f"\\u{ord(m.group()):04x}",
                            json.dumps(value, ensure_ascii=False))


def _value(value: Any) -> str:
    """Any ship-file value (numbers, strings, booleans, mappings, lists) in YAML flow style."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return number(value)
    if isinstance(value, str):
        return text(value)
    if isinstance(value, Mapping):
        return _flow(value)
    if isinstance(value, Sequence):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if value is None:
        return "null"
    raise TypeError(f"cannot write a {type(value).__name__} to a ship file")


def _flow(mapping: Mapping[str, Any]) -> str:
    return "{" + ", ".join(f"{key}: {_value(v)}" for key, v in mapping.items()) + "}"


def render(spec: Mapping[str, Any], name: str, description: str, source: str,
           fitted: Mapping[str, tuple[float, float]]) -> str:
    """Ship-file text of ``spec`` (a parsed ship file) with its coefficients as they are,
    ``fitted`` naming the identified ones ``{name: (value, ci95 half-width)}``."""
    lines = ["schema_version: 1", f"name: {text(name)}", f"description: {text(description)}",
             f"source: {text(source)}", f"model: {spec['model']}", "particulars:"]
    parts = dict(spec["particulars"])
    for key in (*_PARTS_ORDER, *sorted(k for k in parts if k not in _PARTS_ORDER)):
        if key in parts:
            lines.append(f"  {key}: {number(parts[key])}")
    lines.append(f"service_speed_kn: {number(spec['service_speed_kn'])}")
    lines.append(f"actuators: {_flow(spec['actuators'])}")
    lines.append("coefficients:")
    for key, value in spec["coefficients"].items():
        if key in fitted:
            v, ci = fitted[key]
            note = (f"nominal 95 % interval +-{abs(ci):.3g}" if math.isfinite(ci)
                    else "not determined by the data")
            lines.append(f"  {key}: {number(v)}   # identified, {note}")
        else:
            lines.append(f"  {key}: {number(value)}")
    for key in ("autopilot", "integration"):
        if spec.get(key):
            lines.append(f"{key}: {_flow(spec[key])}")
    if spec.get("sensors"):
        lines.append(f"sensors: {_flow(spec['sensors'])}")
    return "\n".join(lines) + "\n"


def write_ship_file(path: Path, spec: Mapping[str, Any], name: str, description: str,
                    source: str, fitted: Mapping[str, tuple[float, float]]) -> dict[str, Any]:
    """Validate the ship file by the library's loader, write it atomically and return it as
    loaded. A spec the loader rejects is a ShipLibraryError naming the key, and nothing is
    written to ``path``."""
    from trafficsim.ships.library import load_ship

    body = render(spec, name, description, source, fitted)
    with tempfile.TemporaryDirectory() as scratch:
        probe = Path(scratch) / "ship.yaml"
        probe.write_text(body, encoding="utf-8")
        try:
            loaded = load_ship(str(probe))
        except ShipLibraryError as err:
            raise ShipLibraryError(f"{err.message} (the identified ship is not a valid ship "
                                   f"file, so {path} was not written)", key=err.key) from None
    atomic_write(path, lambda fh: fh.write(body.encode()))
    loaded["path"] = str(Path(path).resolve())  # (the same text: no second load)
    return loaded
