import math
from statistics import NormalDist

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trafficsim.campaign.summary import (
    Z95,
    completed,
    diverged_encounters,
    per_encounter,
    summarise,
    wilson,
)
from trafficsim.units import NM


def test_wilson_interval_known_values():
    # Wilson (1927) score interval, z = 1.96: 0/10 -> [0, 0.2775]; 5/10 -> [0.2366, 0.7634]
    assert wilson(0, 10) == pytest.approx((0.0, 0.27753), abs=1e-4)
    assert wilson(5, 10) == pytest.approx((0.23659, 0.76341), abs=1e-4)
    assert all(math.isnan(v) for v in wilson(0, 0))
    low, high = wilson(3, 1000)
    assert low < 0.003 < high


@given(st.integers(1, 10**9), st.data())
def test_wilson_interval_holds_the_proportion_and_ends_exactly_at_0_and_1(n, data):
    """No collision in 1,000 encounters reports a lower end of 0, not 2e-19 (rounding)."""
    k = data.draw(st.integers(0, n))
    low, high = wilson(k, n)
    assert 0.0 <= low <= k / n <= high <= 1.0
    assert wilson(0, n)[0] == 0.0 and wilson(n, n)[1] == 1.0


def _rows():
    return {
        "encounter": np.array([0, 1, 1, 1, 2]),
        "encounter_type": np.array(["head_on", "multi", "multi", "multi", "head_on"],
                                   dtype=object),
        "collision": np.array([False, False, True, False, False]),
        "domain_violation": np.array([True, False, True, False, False]),
        "blind_spot": np.zeros(5, dtype=bool),
        "min_range_m": np.array([700.0, 3000.0, 10.0, 2000.0, 1500.0]),
        "behaviour_i": np.array(["colregs"] * 5, dtype=object),
        "behaviour_j": np.array(["colregs", "colregs", "turn_port", "colregs", "colregs"],
                                dtype=object),
        **{f"score_rule{r}": np.array([0.5, np.nan, 0.0, np.nan, 1.0]) for r in
           (13, 14, 15, 16, 17)},
    }


def test_rates_are_per_encounter():
    enc = per_encounter(_rows())
    np.testing.assert_array_equal(enc["collision"], [False, True, False])
    np.testing.assert_array_equal(enc["near_miss"], [True, False, False])  # 700 m < 800 m
    np.testing.assert_array_equal(enc["min_range_m"], [700.0, 10.0, 1500.0])
    np.testing.assert_array_equal(enc["all_compliant"], [True, False, True])
    s = summarise(_rows())
    assert s["n_encounters"] == 3 and s["collisions"] == 1
    assert s["collisions_all_compliant"] == 0 and s["encounters_all_compliant"] == 2
    assert s["domain_violation"]["count"] == 2
    assert s["by_type"]["head_on"]["near_miss"]["count"] == 1
    assert s["by_type"]["multi"]["collision"]["rate"] == 1.0
    assert s["compliance"]["rule14"] == pytest.approx(0.5)
    assert s["cpa_nm"]["p50"] == pytest.approx(700.0 / 1852.0)


# --------------------------------------------------------------------------------------------
# Wilson interval against independent forms
# --------------------------------------------------------------------------------------------

def _wilson_by_inversion(k, n, z):
    """The Wilson interval as the set of p with |k/n - p| <= z sqrt(p (1 - p) / n): the roots
    of (1 + z^2/n) p^2 - (2 k/n + z^2/n) p + (k/n)^2 = 0."""
    ph = k / n
    a = 1 + z * z / n
    b = -(2 * ph + z * z / n)
    c = ph * ph
    disc = math.sqrt(b * b - 4 * a * c)
    return (-b - disc) / (2 * a), (-b + disc) / (2 * a)


def test_z95_is_the_two_sided_95_percent_normal_quantile():
    assert math.isclose(Z95, NormalDist().inv_cdf(0.975), rel_tol=1e-12)


@pytest.mark.parametrize("k, n", [(1, 1), (0, 1), (1, 2), (1, 10), (7, 10), (3, 1000),
                                  (997, 1000), (50, 100), (12345, 1_000_000)])
def test_wilson_is_the_inverted_score_test(k, n):
    """Same interval as solving the score test's quadratic for p."""
    low, high = wilson(k, n)
    ref = _wilson_by_inversion(k, n, Z95)
    assert (low, high) == pytest.approx(ref, abs=1e-12)


def test_wilson_ends_satisfy_the_score_test_with_equality():
    """At each end p of the interval the score statistic |k/n - p| / sqrt(p(1-p)/n) is z."""
    for k, n in ((3, 17), (40, 41), (1, 300)):
        for p in wilson(k, n):
            stat = abs(k / n - p) / math.sqrt(p * (1 - p) / n)
            assert stat == pytest.approx(Z95, rel=1e-9)


def test_wilson_is_symmetric_and_narrows_with_n():
    """wilson(n - k, n) mirrors wilson(k, n) about 1/2; the same proportion on 100 times the
    encounters gives an interval about 10 times narrower; a larger z widens it."""
    low, high = wilson(3, 20)
    mlow, mhigh = wilson(17, 20)
    assert (low, high) == pytest.approx((1 - mhigh, 1 - mlow), abs=1e-12)
    w1 = np.subtract(*wilson(30, 100)[::-1])
    w2 = np.subtract(*wilson(3000, 10000)[::-1])
    assert w1 / w2 == pytest.approx(10.0, rel=0.02)
    assert np.subtract(*wilson(30, 100, z=2.576)[::-1]) > w1


def test_wilson_with_z_zero_is_the_point_estimate():
    assert wilson(3, 8, z=0.0) == pytest.approx((3 / 8, 3 / 8))


# --------------------------------------------------------------------------------------------
# per-encounter collapse, quantiles, per-type statistics, diverged encounters
# --------------------------------------------------------------------------------------------

def _table(enc, kinds, min_range, collision=None, domain=None, blind=None, behaviour_j=None,
           diverged=None, scores=None):
    n = len(enc)
    t = {
        "encounter": np.asarray(enc),
        "encounter_type": np.asarray(kinds, dtype=object),
        "collision": np.zeros(n, bool) if collision is None else np.asarray(collision),
        "domain_violation": np.zeros(n, bool) if domain is None else np.asarray(domain),
        "blind_spot": np.zeros(n, bool) if blind is None else np.asarray(blind),
        "min_range_m": np.asarray(min_range, dtype=float),
        "behaviour_i": np.array(["colregs"] * n, dtype=object),
        "behaviour_j": np.array(["colregs"] * n if behaviour_j is None else behaviour_j,
                                dtype=object),
    }
    for r in (13, 14, 15, 16, 17):
        t[f"score_rule{r}"] = (np.full(n, np.nan) if scores is None
                               else np.asarray(scores.get(r, [np.nan] * n), dtype=float))
    if diverged is not None:
        t["diverged"] = np.asarray(diverged)
    return t


def test_per_encounter_does_not_need_sorted_rows():
    """Rows of an encounter need not be adjacent: shuffling the rows changes nothing."""
    t = _table([2, 0, 1, 2, 0], ["multi", "head_on", "overtaking", "multi", "head_on"],
               [900.0, 100.0, 5000.0, 700.0, 2000.0], collision=[False, True, False, False,
                                                              False])
    rng = np.random.default_rng(0)
    perm = rng.permutation(5)
    a = per_encounter(t)
    b = per_encounter({k: v[perm] for k, v in t.items()})
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    np.testing.assert_array_equal(a["encounter"], [0, 1, 2])
    np.testing.assert_array_equal(a["type"], ["head_on", "overtaking", "multi"])
    np.testing.assert_array_equal(a["min_range_m"], [100.0, 5000.0, 700.0])


def test_near_miss_is_strictly_below_800_m_and_not_a_collision():
    """800 m exactly is not a near miss; 799.9 m is; a collision at 10 m is a collision, not a
    near miss."""
    t = _table([0, 1, 2, 3], ["head_on"] * 4, [800.0, 799.9, 10.0, 5000.0],
               collision=[False, False, True, False])
    enc = per_encounter(t)
    np.testing.assert_array_equal(enc["near_miss"], [False, True, False, False])
    s = summarise(t)
    assert s["near_miss"]["count"] == 1 and s["collision"]["count"] == 1
    assert s["near_miss"]["ci95"] == pytest.approx(list(wilson(1, 4)))


def test_cpa_quantiles_are_linear_percentiles_of_the_per_encounter_minimum():
    """Five encounters with minima 100, 200, 300, 400, 1852 m (the pair rows hold larger
    ranges too): p50 = 300 m; p5 = 100 + 0.2 (200 - 100) = 120 m (position 0.05 * 4 = 0.2);
    p1 = 100 + 0.04 * 100 = 104 m."""
    t = _table([0, 0, 1, 2, 3, 4, 4], ["multi"] * 7,
               [100.0, 900.0, 200.0, 300.0, 400.0, 1852.0, 5000.0])
    s = summarise(t)
    assert s["cpa_nm"]["p50"] == pytest.approx(300.0 / NM)
    assert s["cpa_nm"]["p5"] == pytest.approx(120.0 / NM)
    assert s["cpa_nm"]["p1"] == pytest.approx(104.0 / NM)


def test_per_type_rates_and_intervals_by_hand():
    """Three head-on encounters (one collision), two crossing give-way (none): rates 1/3 and
    0/2 with their own Wilson intervals; types that did not occur are left out."""
    t = _table([0, 1, 2, 3, 4], ["head_on", "crossing_give_way", "head_on", "head_on",
                                 "crossing_give_way"],
               [50.0, 3000.0, 2000.0, 1500.0, 900.0],
               collision=[True, False, False, False, False],
               domain=[True, True, False, False, False])
    s = summarise(t)
    assert set(s["by_type"]) == {"head_on", "crossing_give_way"}
    ho, cg = s["by_type"]["head_on"], s["by_type"]["crossing_give_way"]
    assert ho["n_encounters"] == 3 and cg["n_encounters"] == 2
    assert ho["collision"]["rate"] == pytest.approx(1 / 3)
    assert ho["collision"]["ci95"] == pytest.approx(list(wilson(1, 3)))
    assert cg["collision"] == {"count": 0, "rate": 0.0, "ci95": [0.0, pytest.approx(
        wilson(0, 2)[1])]}
    assert cg["domain_violation"]["count"] == 1
    assert s["collision"]["ci95"] == pytest.approx(list(wilson(1, 5)))
    assert ho["cpa_nm"]["p50"] == pytest.approx(1500.0 / NM)


def test_compliance_means_skip_nan_and_are_split_by_type():
    """Rule means over pair rows ignore NaN (a rule that binds nobody in the pair); a rule with
    no score at all is None (null in summary.json)."""
    t = _table([0, 1, 1, 2], ["head_on", "multi", "multi", "head_on"], [900.0] * 4,
               scores={14: [0.2, np.nan, 0.6, 0.4], 15: [np.nan, 0.9, np.nan, np.nan]})
    s = summarise(t)
    assert s["compliance"]["rule14"] == pytest.approx((0.2 + 0.6 + 0.4) / 3)
    assert s["compliance"]["rule15"] == pytest.approx(0.9)
    assert s["compliance"]["rule13"] is None
    assert s["by_type"]["head_on"]["compliance"]["rule14"] == pytest.approx(0.3)
    assert s["by_type"]["multi"]["compliance"]["rule14"] == pytest.approx(0.6)
    assert s["by_type"]["head_on"]["compliance"]["rule15"] is None


def test_compliant_counts_exclude_any_encounter_with_a_rogue():
    """An encounter with one rogue (or keep-course) ship is not all-compliant; its collision is
    not a collision of compliant ships."""
    t = _table([0, 0, 1, 2], ["multi", "multi", "head_on", "head_on"], [10.0, 900.0, 20.0,
                                                                         3000.0],
               collision=[True, False, True, False],
               behaviour_j=["colregs", "late_action", "colregs", "keep_course"])
    s = summarise(t)
    assert s["collisions"] == 2 and s["collisions_all_compliant"] == 1
    assert s["encounters_all_compliant"] == 1


def test_diverged_encounters_are_counted_apart():
    """Encounter 1 diverged: it is named and counted, and every rate, quantile and score is
    over encounters 0 and 2 only, exactly as if its rows were absent."""
    kinds = ["head_on", "multi", "multi", "head_on"]
    t = _table([0, 1, 1, 2], kinds, [10.0, 0.0, 0.0, 3000.0],
               collision=[True, True, True, False], diverged=[False, True, True, False],
               scores={14: [0.1, 0.9, 0.9, 0.5]})
    s = summarise(t)
    assert s["n_encounters"] == 3 and s["n_completed"] == 2
    assert s["diverged"] == 1 and s["diverged_encounters"] == [1]
    kept = [0, 3]
    without = summarise({k: v[kept] for k, v in t.items() if k != "diverged"})
    for key in ("collision", "near_miss", "cpa_nm", "compliance", "by_type", "collisions"):
        assert s[key] == without[key], key
    assert "multi" not in s["by_type"]
    assert diverged_encounters(t) == [1]
    assert completed(t)["encounter"].tolist() == [0, 2]


def test_a_table_without_the_diverged_column_is_all_completed():
    t = _table([0, 1], ["head_on", "head_on"], [500.0, 900.0])
    assert diverged_encounters(t) == [] and len(completed(t)["encounter"]) == 2
    assert summarise(t)["n_completed"] == 2


def test_all_diverged_gives_no_rates_rather_than_an_error():
    """Nothing ran to the end: counts 0, rates, intervals and quantiles NaN, scores None,
    no per-type entries."""
    t = _table([0, 1, 1], ["head_on", "multi", "multi"], [10.0, 20.0, 30.0],
               diverged=[True, True, True], scores={14: [0.5, 0.5, 0.5]})
    s = summarise(t)
    assert s["n_encounters"] == 2 and s["n_completed"] == 0 and s["diverged"] == 2
    assert s["collision"]["count"] == 0 and math.isnan(s["collision"]["rate"])
    assert all(math.isnan(v) for v in s["collision"]["ci95"])
    assert all(math.isnan(v) for v in s["cpa_nm"].values())
    assert all(v is None for v in s["compliance"].values())
    assert s["by_type"] == {}


def test_an_empty_table_summarises():
    t = _table([], [], [])
    s = summarise(t)
    assert s["n_encounters"] == 0 and s["n_completed"] == 0 and s["by_type"] == {}


# --------------------------------------------------------------------------------------------
# against scipy, and against per-encounter loops on random tables
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("k, n", [(0, 1), (1, 1), (0, 7), (3, 7), (7, 7), (1, 1000),
                                  (999, 1000), (500, 1000), (17, 123456)])
@pytest.mark.parametrize("level", [0.95, 0.9, 0.99])
def test_wilson_matches_scipy(k, n, level):
    """scipy.stats.binomtest(k, n).proportion_ci(method="wilson") at the same level (z the
    normal quantile of (1 + level) / 2)."""
    from scipy import stats

    z = stats.norm.ppf(0.5 + level / 2)
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=level, method="wilson")
    low, high = wilson(k, n, z) if level != 0.95 else wilson(k, n)
    assert low == pytest.approx(max(0.0, ci.low), abs=1e-12)
    assert high == pytest.approx(min(1.0, ci.high), abs=1e-12)


def _random_table(rng, n_enc, diverged=False):
    kinds = ["head_on", "crossing_give_way", "overtaking", "multi"]
    enc, kind, rng_m, coll, dom, blind, beh = [], [], [], [], [], [], []
    for e in rng.permutation(n_enc) + 100:
        k = kinds[rng.integers(len(kinds))]
        for _ in range(rng.integers(3, 7) if k == "multi" else 1):
            enc.append(int(e))
            kind.append(k)
            rng_m.append(float(rng.choice([rng.uniform(0, 300), rng.uniform(300, 4000)])))
            coll.append(rng_m[-1] < 100 and rng.random() < 0.8)
            dom.append(rng_m[-1] < 1500 and rng.random() < 0.7)
            blind.append(bool(rng.random() < 0.1))
            beh.append("colregs" if rng.random() < 0.9 else "turn_port")
    scores = {r: np.where(rng.random(len(enc)) < 0.5, np.nan, rng.random(len(enc)))
              for r in (13, 14, 15, 16, 17)}
    t = _table(enc, kind, rng_m, collision=coll, domain=dom, blind=blind, behaviour_j=beh,
               scores=scores)
    if diverged:
        bad = set(rng.choice(np.unique(enc), size=3, replace=False).tolist())
        t["diverged"] = np.array([e in bad for e in enc])
    return t


def _per_encounter_by_loop(t):
    out: dict = {}
    for i, e in enumerate(t["encounter"].tolist()):
        if "diverged" in t and t["diverged"][i]:
            continue
        row = out.setdefault(e, {"type": t["encounter_type"][i], "min": math.inf,
                                 "collision": False, "domain": False, "blind": False,
                                 "compliant": True})
        row["min"] = min(row["min"], t["min_range_m"][i])
        row["collision"] |= bool(t["collision"][i])
        row["domain"] |= bool(t["domain_violation"][i])
        row["blind"] |= bool(t["blind_spot"][i])
        row["compliant"] &= t["behaviour_i"][i] == "colregs" == t["behaviour_j"][i]
    return out


@pytest.mark.parametrize("seed, diverged", [(0, False), (1, False), (2, True)])
def test_summary_agrees_with_a_loop_over_encounters_and_scipy_quantiles(seed, diverged):
    """Random pair tables (shuffled rows, multi-ship encounters, some rogues, some diverged):
    counts, Wilson intervals, CPA quantiles (scipy's scoreatpercentile, linear interpolation)
    and rule means overall and per type equal those worked out by a plain loop."""
    from scipy import stats

    rng = np.random.default_rng(seed)
    t = _random_table(rng, 60, diverged)
    s = summarise(t)
    enc = _per_encounter_by_loop(t)
    keep = ~t["diverged"] if diverged else np.ones(len(t["encounter"]), bool)
    groups = {"all": list(enc.values())}
    for row in enc.values():
        groups.setdefault(row["type"], []).append(row)
    assert s["n_completed"] == len(enc) and s["n_encounters"] == 60
    assert s["diverged"] == (3 if diverged else 0)
    assert s["collisions_all_compliant"] == sum(r["collision"] and r["compliant"]
                                                for r in enc.values())
    assert s["encounters_all_compliant"] == sum(r["compliant"] for r in enc.values())
    for name, rows in groups.items():
        part = s if name == "all" else s["by_type"][name]
        n = len(rows)
        counts = {"collision": sum(r["collision"] for r in rows),
                  "near_miss": sum(r["min"] < 800 and not r["collision"] for r in rows),
                  "domain_violation": sum(r["domain"] for r in rows),
                  "blind_spot": sum(r["blind"] for r in rows)}
        for key, k in counts.items():
            assert part[key]["count"] == k, (name, key)
            assert part[key]["rate"] == pytest.approx(k / n)
            assert part[key]["ci95"] == pytest.approx(list(wilson(k, n)), abs=1e-15)
        minima = np.array([r["min"] for r in rows]) / NM
        for q in (1, 5, 50):
            assert part["cpa_nm"][f"p{q}"] == pytest.approx(
                stats.scoreatpercentile(minima, q), rel=1e-12)
        sel = keep & (True if name == "all" else t["encounter_type"] == name)
        for r in (13, 14, 15, 16, 17):
            values = [v for v in t[f"score_rule{r}"][sel] if not math.isnan(v)]
            mean = part["compliance"][f"rule{r}"]
            assert (mean is None) if not values else mean == pytest.approx(np.mean(values))
    assert set(s["by_type"]) == set(groups) - {"all"}


def test_one_encounter_gives_its_minimum_for_every_quantile():
    """A single encounter of three pairs: P1 = P5 = P50 = its smallest range; its collision
    rate is 1 of 1 with the Wilson interval [0.2065, 1] (z = 1.96: 1 / (1 + z^2) = 0.2066)."""
    t = _table([4, 4, 4], ["multi"] * 3, [2500.0, 900.0, 50.0], collision=[False, False, True])
    s = summarise(t)
    assert s["cpa_nm"] == pytest.approx({f"p{q}": 50.0 / NM for q in (1, 5, 50)})
    assert s["collision"]["ci95"] == pytest.approx([1 / (1 + Z95**2), 1.0], abs=1e-12)
    assert s["near_miss"]["count"] == 0  # the encounter collided


def test_per_type_split_counts_each_encounter_once():
    """The per-type encounter counts add up to the completed encounters."""
    t = _random_table(np.random.default_rng(5), 40, diverged=True)
    s = summarise(t)
    assert sum(v["n_encounters"] for v in s["by_type"].values()) == s["n_completed"] == 37


def test_encounters_with_a_pair_still_closing_at_their_end_are_counted():
    """An encounter counts in ``cpa_not_passed`` when any of its pairs had not passed its
    closest point when the encounter ended, overall and by type; a diverged one does not; a
    table from before the column counts none."""
    t = _table([0, 1, 1, 2, 3], ["head_on", "multi", "multi", "head_on", "head_on"],
               [900.0, 2000.0, 1500.0, 1200.0, 700.0], diverged=[False] * 4 + [True])
    t["cpa_passed"] = np.array([True, True, False, False, False])
    s = summarise(t)
    assert s["cpa_not_passed"] == 2
    assert s["by_type"]["multi"]["cpa_not_passed"] == 1
    assert s["by_type"]["head_on"]["cpa_not_passed"] == 1
    del t["cpa_passed"]
    assert summarise(t)["cpa_not_passed"] == 0
