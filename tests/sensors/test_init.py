"""Shared sensor helpers: angle wrapping (array and compiled scalar forms), Gauss-Markov
coefficients, the body-to-earth rotation and the config readers."""

import math

import numpy as np
import pytest

from trafficsim.errors import InputError
from trafficsim.sensors import (
    TWO_PI,
    check_keys,
    choice,
    column,
    flags,
    gauss_markov,
    mod_2pi_scalar,
    rotate_body_to_earth,
    wrap_2pi,
    wrap_2pi_scalar,
    wrap_pi,
)


def _angles():
    """Angles around every multiple of 2 pi that matters, tiny ones and large ones."""
    rng = np.random.default_rng(0)
    special = [0.0, 1e-300, -1e-300, 1e-17, -1e-17, math.pi, -math.pi, TWO_PI, -TWO_PI,
               2 * TWO_PI, -2 * TWO_PI, math.nextafter(TWO_PI, 0.0),
               -math.nextafter(TWO_PI, 0.0), math.nextafter(TWO_PI, 10.0), 7.0, -7.0, 1e20,
               -1e20, 123456.789]
    return np.concatenate([special, rng.uniform(-50.0, 50.0, 2000),
                           rng.uniform(-TWO_PI, TWO_PI, 2000)])


def test_wrap_2pi_range_and_whole_turns():
    """The result lies in [0, 2 pi) and differs from the angle by whole turns."""
    a = _angles()
    w = wrap_2pi(a)
    assert np.all((w >= 0.0) & (w < TWO_PI))
    small = np.abs(a) < 1e3  # whole turns are resolvable to 1e-12 there
    turns = (a[small] - w[small]) / TWO_PI
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-12)
    assert wrap_2pi(np.array([-1e-17]))[0] == 0.0  # np.mod alone gives 2 pi here
    with np.errstate(invalid="ignore"):
        assert np.isnan(wrap_2pi(np.array([math.nan, math.inf]))).all()


def test_compiled_scalars_are_numpy_bit_for_bit():
    """``mod_2pi_scalar`` is ``np.mod(a, 2 pi)`` and ``wrap_2pi_scalar`` is ``wrap_2pi``,
    bit for bit (documented), on both sides of every multiple of 2 pi."""
    a = _angles()
    mod = np.array([mod_2pi_scalar(float(v)) for v in a])
    wrap = np.array([wrap_2pi_scalar(float(v)) for v in a])
    np.testing.assert_array_equal(mod.view(np.uint64), np.mod(a, TWO_PI).view(np.uint64))
    np.testing.assert_array_equal(wrap.view(np.uint64), wrap_2pi(a).view(np.uint64))


def test_compiled_wrap_of_negative_zero_is_numpy_bit_for_bit():
    """``np.mod(-0.0, 2 pi)`` is +0.0 (numpy gives a zero remainder the divisor's sign); the
    compiled form must give the same bits, as its docstring says."""
    assert not np.signbit(np.mod(-0.0, TWO_PI))
    assert not np.signbit(wrap_2pi(np.array([-0.0]))[0])
    assert not np.signbit(mod_2pi_scalar(-0.0))
    assert not np.signbit(wrap_2pi_scalar(-0.0))


def test_wrap_pi_range_and_whole_turns():
    a = _angles()
    w = wrap_pi(a)
    assert np.all((w >= -math.pi) & (w < math.pi))
    small = np.abs(a) < 1e3
    turns = (a[small] - w[small]) / TWO_PI
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-12)
    # the half-open end: +pi and -pi both map to -pi, 3 pi too
    np.testing.assert_allclose(wrap_pi(np.array([math.pi, -math.pi, 3 * math.pi])), -math.pi)


@pytest.mark.parametrize("dt", [0.01, 1.0, 50.0, 5000.0])
def test_gauss_markov_coefficients_stationary_and_compose(dt):
    """``a = exp(-dt/tau)``; the variance ``a^2 s^2 + q^2`` stays ``s^2``; two steps of
    ``dt/2`` are one step of ``dt`` (the discretisation is exact, not Euler)."""
    sigma = np.array([0.0, 1.0, 3.5])
    tau = np.array([10.0, 60.0, 0.5])
    a, q = gauss_markov(sigma, tau, dt)
    np.testing.assert_allclose(a, np.exp(-dt / tau), rtol=1e-15)
    np.testing.assert_allclose(a * a * sigma**2 + q * q, sigma**2, rtol=1e-12, atol=1e-300)
    ah, qh = gauss_markov(sigma, tau, dt / 2.0)
    np.testing.assert_allclose(ah * ah, a, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(ah * ah * qh * qh + qh * qh, q * q, rtol=1e-10, atol=1e-300)
    assert np.all(q >= 0.0)


def test_rotate_body_to_earth_is_the_seed_003_rotation():
    """Seed 003 eq 5: ``x + w_x cos psi - w_y sin psi``, ``y + w_y cos psi + w_x sin psi``;
    a rotation (length kept) that is the same at psi and psi + 2 pi."""
    rng = np.random.default_rng(1)
    psi = rng.uniform(-10.0, 10.0, 500)
    bx, by = rng.normal(0.0, 30.0, (2, 500))
    n, e = rotate_body_to_earth(psi, bx, by)
    np.testing.assert_allclose(n, bx * np.cos(psi) - by * np.sin(psi), rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(e, by * np.cos(psi) + bx * np.sin(psi), rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(np.hypot(n, e), np.hypot(bx, by), rtol=1e-13)
    n2, e2 = rotate_body_to_earth(psi + TWO_PI, bx, by)
    np.testing.assert_allclose(np.stack([n2, e2]), np.stack([n, e]), atol=1e-10)
    # heading east: forward points east, starboard points south
    n, e = rotate_body_to_earth(np.array([math.pi / 2]), np.array([1.0]), np.array([0.0]))
    assert (n[0], e[0]) == pytest.approx((0.0, 1.0), abs=1e-15)
    n, e = rotate_body_to_earth(np.array([math.pi / 2]), np.array([0.0]), np.array([1.0]))
    assert (n[0], e[0]) == pytest.approx((-1.0, 0.0), abs=1e-15)


def test_column_defaults_scale_and_per_ship_default():
    cfgs = [{"k": 2}, {}, {"k": None}, {"k": 0.5}]
    out = column(cfgs, "k", [10.0, 20.0, 30.0, 40.0], "sec", scale=3.0)
    np.testing.assert_array_equal(out, [6.0, 60.0, 90.0, 1.5])
    assert column([], "k", 1.0, "sec").shape == (0,)


@pytest.mark.parametrize(("value", "minimum", "strictly", "match"), [
    (-1.0, 0.0, False, ">= 0.0"),
    (0.0, 0.0, True, "> 0.0"),
    (math.nan, None, False, "finite"),
    (math.inf, None, False, "finite"),
    (-math.inf, 0.0, False, "finite"),
    ("abc", None, False, "expected a number"),
    ([1.0], None, False, "expected a number"),
    ({"a": 1}, None, False, "expected a number"),
])
def test_column_errors_name_ship_and_key(value, minimum, strictly, match):
    """The second ship's bad value is reported as ``sec[1].k``; the first is fine."""
    with pytest.raises(InputError, match=match) as err:
        column([{"k": 1.0}, {"k": value}], "k", 0.0, "sec", minimum=minimum, strictly=strictly)
    assert err.value.key == "sec[1].k"


def test_column_minimum_is_inclusive_unless_strict():
    assert column([{"k": 0.0}], "k", 1.0, "s", minimum=0.0)[0] == 0.0
    assert column([{"k": 1e-300}], "k", 1.0, "s", minimum=0.0, strictly=True)[0] == 1e-300


@pytest.mark.parametrize(("values", "strictly_max", "message"), [
    ([1.0, 1000.5], False, "must be <= 1000, got 1000.5"),
    ([1.0, 1e9], False, "must be <= 1000, got 1000000000.0"),
    ([1.0, 1000], True, "must be < 1000, got 1000.0"),
])
def test_column_maximum_errors_name_ship_and_key(values, strictly_max, message):
    """Above the maximum (or at it, with ``strictly_max``) is refused in the minimum's style,
    naming the second ship's key; the first ship's value is fine."""
    with pytest.raises(InputError) as err:
        column([{"k": v} for v in values], "k", 0.0, "sec", minimum=0.0, maximum=1000,
               strictly_max=strictly_max)
    assert err.value.key == "sec[1].k"
    assert err.value.message == message


def test_column_maximum_is_inclusive_unless_strict_and_in_config_units():
    """The bound applies to the value as written (before ``scale``), defaults included, on the
    fast path (plain numbers) and the slow one (other number types) alike."""
    out = column([{"k": 30}, {"k": np.float32(29.5)}, {}], "k", 30.0, "s", scale=0.5,
                 maximum=30)
    np.testing.assert_array_equal(out, [15.0, 14.75, 15.0])
    assert column([{"k": math.nextafter(1.0, 0.0)}], "k", 0.0, "s", maximum=1.0,
                  strictly_max=True)[0] < 1.0
    for cfgs in ([{"k": 30.000001}], [{"k": np.float64(31.0)}], [{}]):
        with pytest.raises(InputError, match="<= 30") as err:
            column(cfgs, "k", 31.0, "s", scale=0.5, maximum=30)
        assert err.value.key == "s[0].k"
    with pytest.raises(InputError, match="< 1") as err:
        column([{"k": 0.5}, {"k": np.float64(1.0)}], "k", 0.0, "s", maximum=1,
               strictly_max=True)
    assert err.value.key == "s[1].k"


def test_column_two_sided_bounds():
    np.testing.assert_array_equal(
        column([{"k": -180}, {"k": 180.0}], "k", 0.0, "s", minimum=-180, maximum=180),
        [-180.0, 180.0])
    for bad, match in ((-180.5, ">= -180"), (180.5, "<= 180")):
        with pytest.raises(InputError, match=match):
            column([{"k": bad}], "k", 0.0, "s", minimum=-180, maximum=180)


def test_column_integer_beyond_float_range_is_an_input_error():
    """YAML reads a long digit string as a Python int; ``float()`` of it overflows. The
    project treats that as an input error naming the key, not a crash."""
    with pytest.raises(InputError) as err:
        column([{"k": 10**400}], "k", 0.0, "sec", minimum=0.0)
    assert err.value.key == "sec[0].k"


def test_column_boolean_is_not_a_number():
    """``sigma_m: yes`` is a mistake, not 1.0: booleans are not numbers in the project's other
    readers (effects, ship library), and ``column`` says 'expected a number'."""
    with pytest.raises(InputError) as err:
        column([{"k": True}], "k", 0.0, "sec")
    assert err.value.key == "sec[0].k"


def test_flags_choice_and_check_keys():
    np.testing.assert_array_equal(flags([{}, {"f": False}], "f", "sec"), [True, False])
    np.testing.assert_array_equal(flags([{}], "f", "sec", default=False), [False])
    for bad in (1, "true", None, 0.0):
        with pytest.raises(InputError, match="true or false") as err:
            flags([{}, {"f": bad}], "f", "sec")
        assert err.value.key == "sec[1].f"
    assert choice([{}, {"c": "b"}], "c", ("a", "b"), "a", "sec") == ["a", "b"]
    with pytest.raises(InputError, match="expected one of") as err:
        choice([{"c": "a"}, {}], "c", ("a", "b"), None, "sec")  # required key missing
    assert err.value.key == "sec[1].c"
    check_keys([{"a": 1}, {}], ("a", "b"), "sec")
    with pytest.raises(InputError, match=r"\['zz'\]") as err:
        check_keys([{"a": 1}, {"a": 1, "zz": 2}], ("a", "b"), "sec")
    assert err.value.key == "sec[1]"
