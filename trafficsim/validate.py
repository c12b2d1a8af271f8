"""``trafficsim validate``: check scenario and ship files without running them."""

from __future__ import annotations

from pathlib import Path

from trafficsim.errors import InputError


def validate_file(path: Path) -> list[InputError]:
    """All errors found in ``path`` (a scenario or a ship file, told apart by its keys)."""
    from trafficsim.io.yamlio import load_yaml

    try:
        doc = load_yaml(path)
        if isinstance(doc.data, dict) and "model" in doc.data and "ships" not in doc.data:
            from trafficsim.ships.library import load_ship

            load_ship(str(path.resolve()))
        else:
            from trafficsim.io.scenario import load_scenario
            from trafficsim.ships.library import load_ship

            for ship_file in load_scenario(path).ship_files:
                load_ship(str(ship_file))
    except InputError as err:
        return list(getattr(err, "errors", None) or [err])
    return []
