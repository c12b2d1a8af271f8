"""Campaign figures (trafficsim.campaign.figures): the two PNG files and the data they are drawn
from, caught on its way into matplotlib and checked against values worked out here from the rows
(encounters that diverged left out, outcomes per encounter, Wilson 95 % intervals)."""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from trafficsim.campaign.figures import write_figures
from trafficsim.units import NM

Z95 = 1.959963984540054  # standard normal quantile of 0.975

# (encounter, type, smallest range m, domain entered, collision, diverged): encounter 6 diverged
PAIRS = [
    (0, "head_on", 500.0, False, False, False),  # near miss
    (1, "head_on", 1500.0, True, False, False),  # domain entered only
    (2, "head_on", 3000.0, False, False, False),  # safe
    (3, "crossing_give_way", 150.0, True, True, False),  # collision
    (4, "crossing_give_way", 700.0, True, False, False),  # near miss
    (5, "multi", 100.0, False, True, False),  # multi: one collision,
    (5, "multi", 900.0, True, False, False),  # one domain entry,
    (5, "multi", 2500.0, False, False, False),  # one safe pair
    (6, "overtaking", 50.0, True, True, True),  # diverged: in no figure
    (6, "overtaking", 60.0, True, True, True),
]
# per kind drawn, in ENCOUNTER_TYPES order: (collisions, near misses, domain entries, encounters)
EXPECTED = {"head_on": (0, 1, 1, 3), "crossing_give_way": (1, 1, 2, 2), "multi": (1, 0, 1, 1)}


def _rows(pairs: list[tuple], diverged: bool = True) -> dict[str, np.ndarray]:
    n = len(pairs)
    rows = {"encounter": np.array([p[0] for p in pairs]),
            "encounter_type": np.array([p[1] for p in pairs], dtype=object),
            "min_range_m": np.array([p[2] for p in pairs]),
            "domain_violation": np.array([p[3] for p in pairs]),
            "collision": np.array([p[4] for p in pairs]),
            "blind_spot": np.zeros(n, dtype=bool),
            "behaviour_i": np.array(["colregs"] * n, dtype=object),
            "behaviour_j": np.array(["colregs"] * n, dtype=object)}
    if diverged:
        rows["diverged"] = np.array([p[5] for p in pairs])
    return rows


def _wilson(k: int, n: int) -> tuple[float, float]:
    p = k / n
    centre = (p + Z95**2 / (2 * n)) / (1 + Z95**2 / n)
    half = Z95 / (1 + Z95**2 / n) * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


class Drawn:
    """The calls of the drawing methods write_figures uses, with their arguments and results."""

    def __init__(self) -> None:
        self.calls: dict[str, list[tuple[tuple, dict, Any]]] = {}

    def spy(self, monkeypatch: pytest.MonkeyPatch, cls: type, name: str) -> None:
        original = getattr(cls, name)

        def wrapper(obj: Any, *args: Any, **kwargs: Any) -> Any:
            result = original(obj, *args, **kwargs)
            self.calls.setdefault(name, []).append((args, kwargs, result))
            return result

        monkeypatch.setattr(cls, name, wrapper)


def _draw(rows: dict[str, np.ndarray], out: Path) -> tuple[list[Path], dict[str, list]]:
    from matplotlib.axes import Axes

    drawn = Drawn()
    with pytest.MonkeyPatch.context() as mp:
        for name in ("hist", "bar", "axvline", "set_xticks"):
            drawn.spy(mp, Axes, name)
        paths = write_figures(rows, out)
    return paths, drawn.calls


def _rate_bars(calls: dict[str, list]) -> list[tuple[tuple, dict, Any]]:
    """The bars of the rates figure (hist draws its own bars through Axes.bar too)."""
    return [c for c in calls["bar"] if "yerr" in c[1]]


@pytest.fixture(scope="module")
def drawn(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path], dict]:
    out = tmp_path_factory.mktemp("figures")
    paths, calls = _draw(_rows(PAIRS), out)
    return out, paths, calls


def test_both_figures_are_written_as_pngs_of_800_by_450(drawn):
    out, paths, _ = drawn
    assert paths == [out / "cpa_histogram.png", out / "rates_by_type.png"]
    for path in paths:
        assert _png_size(path) == (800, 450)


def test_the_figures_are_not_blank(drawn):
    from PIL import Image

    _, paths, _ = drawn
    for path in paths:
        with Image.open(path) as image:
            assert len(image.convert("RGB").getcolors(maxcolors=1 << 20)) > 10


def test_the_histogram_splits_the_pairs_of_completed_encounters_by_domain_entry(drawn):
    _, _, calls = drawn
    ((args, kwargs, (counts, edges, _)),) = calls["hist"]
    kept, entered = args[0]
    done = [p for p in PAIRS if not p[5]]
    assert sorted(kept) == pytest.approx(sorted(p[2] / NM for p in done if not p[3]))
    assert sorted(entered) == pytest.approx(sorted(p[2] / NM for p in done if p[3]))
    assert kwargs["stacked"] is True
    assert kwargs["label"] == ["domain kept", "domain entered"]
    # every range here is under 2 NM: the bins span 0 .. 2 NM in 40 bins, and counts add up
    assert edges == pytest.approx(np.linspace(0.0, 2.0, 41))
    assert counts[-1].sum() == len(done)  # stacked: the top layer holds both sets


def test_the_histogram_bins_follow_the_99th_percentile_above_2_nm(tmp_path):
    ranges_nm = np.linspace(0.5, 6.5, 50)
    pairs = [(k, "head_on", r * NM, bool(k % 2), False, False) for k, r in enumerate(ranges_nm)]
    _, calls = _draw(_rows(pairs), tmp_path)
    (_, _, (_, edges, _)), = calls["hist"]
    assert edges[0] == 0.0 and len(edges) == 41
    assert edges[-1] == pytest.approx(np.percentile(ranges_nm, 99))


def test_the_compliance_ranges_are_marked_on_the_histogram(drawn):
    _, _, calls = drawn
    assert [c[0][0] for c in calls["axvline"]] == pytest.approx(
        [200.0 / NM, 800.0 / NM, 1000.0 / NM])


def test_rates_are_drawn_per_encounter_type_present_in_the_standard_order(drawn):
    _, _, calls = drawn
    ((args, _, _),) = calls["set_xticks"]
    assert list(args[0]) == [0, 1, 2]
    assert list(args[1]) == ["head on", "crossing give way", "multi"]  # no diverged overtaking


@pytest.mark.parametrize(("j", "outcome", "label"), [
    (0, "collision", "collision"), (1, "near_miss", "near miss"),
    (2, "domain_violation", "domain violation")])
def test_each_outcome_is_drawn_as_its_rate_per_encounter_with_a_wilson_interval(
        drawn, j, outcome, label):
    _, _, calls = drawn
    assert len(_rate_bars(calls)) == 3
    args, kwargs, _ = _rate_bars(calls)[j]
    x, heights, width = args
    assert kwargs["label"] == label
    assert list(x) == pytest.approx([k + (j - 1) * width for k in range(3)])
    column = ("collision", "near_miss", "domain_violation").index(outcome)
    rates, low, high = [], [], []
    for counts in EXPECTED.values():
        k, n = counts[column], counts[3]
        lo, hi = _wilson(k, n)
        rates.append(k / n)
        low.append(k / n - lo)
        high.append(hi - k / n)
    assert heights == pytest.approx(rates)
    assert kwargs["yerr"][0] == pytest.approx(low, abs=1e-12)
    assert kwargs["yerr"][1] == pytest.approx(high, abs=1e-12)


def test_without_a_diverged_column_every_encounter_is_counted(tmp_path):
    pairs = [p for p in PAIRS if p[1] != "overtaking"] + [(6, "overtaking", 300.0, True, False,
                                                           False)]
    _, calls = _draw(_rows(pairs, diverged=False), tmp_path)
    (_, _, (counts, _, _)), = calls["hist"]
    assert counts[-1].sum() == len(pairs)
    labels = list(calls["set_xticks"][0][0][1])
    assert labels == ["head on", "crossing give way", "overtaking", "multi"]
    # the overtaking encounter: a near miss (300 m, no collision) that entered the domain
    assert [bar[0][1][2] for bar in _rate_bars(calls)] == [0.0, 1.0, 1.0]


def test_a_campaign_whose_encounters_all_diverged_still_gets_both_figures(tmp_path):
    pairs = [(k, "head_on", 100.0 * (k + 1), False, False, True) for k in range(3)]
    paths, calls = _draw(_rows(pairs), tmp_path)
    assert all(_png_size(p) == (800, 450) for p in paths)
    (args, _, (counts, _, _)), = calls["hist"]
    assert [len(a) for a in args[0]] == [0, 0] and counts[-1].sum() == 0
    bars = _rate_bars(calls)
    assert len(bars) == 3 and all(len(bar[0][1]) == 0 for bar in bars)


def test_the_histogram_counts_every_pair(tmp_path):
    ranges_nm = np.linspace(0.1, 10.0, 100)
    pairs = [(k, "head_on", r * NM, False, False, False) for k, r in enumerate(ranges_nm)]
    _, calls = _draw(_rows(pairs), tmp_path)
    (_, _, (counts, _, _)), = calls["hist"]
    assert counts[-1].sum() == len(pairs)


def test_pairs_beyond_the_last_bin_are_counted_in_it(tmp_path):
    """Ranges 0.1, 0.2, ..., 9.9 NM and one pair at 50 NM: the bins end at the linear 99th
    percentile, 9.9 + 0.01 (50 - 9.9) = 10.301 NM (position 0.99 * 99 = 98.01), 40 bins of
    0.2575 NM; the 50 NM pair lands in the last bin (alone: 9.9 < 10.301 - 0.2575), the
    9.9 NM pair in bin 38, and no pair is lost."""
    ranges_nm = [k / 10 for k in range(1, 100)] + [50.0]
    pairs = [(k, "head_on", r * NM, False, False, False) for k, r in enumerate(ranges_nm)]
    _, calls = _draw(_rows(pairs), tmp_path)
    (_, _, (counts, edges, _)), = calls["hist"]
    assert edges[-1] == pytest.approx(10.301)
    total = counts[-1]
    assert total.sum() == 100 and total[-1] == 1
    assert total[38] >= 1 and edges[38] <= 9.9 < edges[39]


def test_a_type_where_every_encounter_collided_has_no_upper_error_bar(tmp_path):
    """Four head-on encounters, all collisions at 50 m: rate 1, the Wilson upper end exactly
    1 (no bar above) and the lower end 4 / (4 + z^2) = 0.5101 (k = n: centre - half reduces
    to n / (n + z^2)); near misses 0 of 4 (a collision is not a near miss)."""
    pairs = [(k, "head_on", 50.0, True, True, False) for k in range(4)]
    _, calls = _draw(_rows(pairs, diverged=False), tmp_path)
    collision, near, domain = _rate_bars(calls)
    assert list(collision[0][1]) == [1.0] and list(near[0][1]) == [0.0]
    assert list(domain[0][1]) == [1.0]
    assert collision[1]["yerr"][1] == [0.0]
    assert collision[1]["yerr"][0] == pytest.approx([1 - 4 / (4 + Z95**2)], abs=1e-12)
    assert near[1]["yerr"][1] == pytest.approx([Z95**2 / (4 + Z95**2)], abs=1e-12)
