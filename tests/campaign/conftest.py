from pathlib import Path

import pytest

SMALL = """schema_version: 1
name: small
n_encounters: {n}
seed: 11
duration_s: {duration}
chunk_encounters: {chunk}
ship_types: {{cargo: 2, container: 1, fishing: 1}}
rogue_fraction: {rogue}
{extra}
"""


@pytest.fixture
def write_spec(tmp_path: Path):
    """Write a small campaign spec; returns its path. A ``duration`` shorter than the default
    TCPA range's 30 min comes with ``tcpa_min`` from a third of it to all of it (at least
    1 min) unless ``extra`` sets one, so that every encounter reaches its CPA, as a spec must."""

    def write(n: int = 6, chunk: int = 2, duration: float = 1800, extra: str = "",
              name: str = "spec.yaml", rogue: float = 0.2) -> Path:
        if duration < 1800 and "tcpa_min" not in extra:
            extra += f"\ntcpa_min: [{max(1.0, duration / 180):g}, {duration / 60:g}]"
        path = tmp_path / name
        path.write_text(SMALL.format(n=n, chunk=chunk, duration=duration, extra=extra,
                                     rogue=rogue))
        return path

    return write


@pytest.fixture
def runaway_ship(tmp_path: Path) -> Path:
    """A ship file whose model runs away: the library bulk carrier with its resistance
    coefficient a1 made a large thrust, so its speed leaves the finite numbers within a
    minute."""
    from trafficsim.ships.library import LIBRARY_DIR

    text = (LIBRARY_DIR / "bulk_carrier.yaml").read_text()
    assert "  a1: -1.4347e-4\n" in text
    path = tmp_path / "runaway.yaml"
    path.write_text(text.replace("  a1: -1.4347e-4\n", "  a1: 1.0e-2\n")
                    .replace("name: bulk_carrier", "name: runaway"))
    return path
