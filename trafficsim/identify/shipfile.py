"""Writing an identified ship as a ship file (the schema of ``trafficsim/ships/library/*.yaml``).

The file is written as plain YAML text (atomically), with the fitted coefficients marked and
their nominal 95 % intervals as comments, and then read back through the ship-library loader,
so a file that the loader would reject is never reported as a result.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

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


def text(value: str) -> str:
    """A string as a YAML double-quoted scalar (JSON escapes are valid YAML escapes)."""
    return json.dumps(value, ensure_ascii=False)


def _flow(mapping: Mapping[str, Any]) -> str:
    items = []
    for key, value in mapping.items():
        if isinstance(value, Mapping):
            items.append(f"{key}: {_flow(value)}")
        elif isinstance(value, bool):
            items.append(f"{key}: {'true' if value else 'false'}")
        elif isinstance(value, (int, float)):
            items.append(f"{key}: {number(value)}")
        elif isinstance(value, str):
            items.append(f"{key}: {text(value)}")
        elif isinstance(value, Sequence):
            items.append(f"{key}: [{', '.join(number(v) for v in value)}]")
        else:
            raise TypeError(f"cannot write {key}: {type(value).__name__}")
    return "{" + ", ".join(items) + "}"


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
            lines.append(f"  {key}: {number(v)}   # identified, nominal 95 % interval "
                         f"+-{abs(ci):.3g}")
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
    """Write the ship file atomically and return it as loaded (validated) by the library."""
    from trafficsim.ships.library import load_ship

    body = render(spec, name, description, source, fitted)
    atomic_write(path, lambda fh: fh.write(body.encode()))
    return load_ship(str(Path(path).resolve()))
