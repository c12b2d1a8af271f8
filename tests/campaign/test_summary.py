import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trafficsim.campaign.summary import per_encounter, summarise, wilson


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
