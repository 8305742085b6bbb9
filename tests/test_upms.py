"""The one UPMS coefficient alpha(U) = 1 - tanh(c U) (crossing_assist.upms), which the runtime's
gate and the IIL mixing laws share: its values and its contract for inf, NaN and negatives."""

import math

import numpy as np
import pytest

from crossing_assist.upms import SATURATION_HALF, coefficient, saturation


def test_it_is_one_minus_tanh_and_one_half_at_the_threshold():
    for t in (0.01, 0.2, 1.0, 1.2, 7.5):
        assert coefficient(t, saturation(t)) == pytest.approx(0.5, abs=1e-15)
    assert SATURATION_HALF == pytest.approx(math.atanh(0.5), abs=0)
    us = np.linspace(0.0, 3.0, 301)
    for c in (0.3, SATURATION_HALF, 3.0):
        got = np.array([coefficient(u, c) for u in us])
        assert np.allclose(got, 1.0 - np.tanh(c * us), rtol=0, atol=4e-16)
        assert got[0] == 1.0 and np.all(np.diff(got) < 0) and np.all(got > 0)


def test_large_uncertainties_stay_ordered_instead_of_cancelling_to_zero():
    """1 - tanh(30 U) is exactly 0 in floating point for U > 0.63; the shared form keeps the
    ratio of two such coefficients (the rational law's input) right: (1 - tanh a)/(1 - tanh b)
    -> exp(2(b - a))."""
    c = 30.0
    a1, a2 = coefficient(1.0, c), coefficient(1.1, c)
    assert 1.0 - math.tanh(c * 1.0) == 0.0 and a1 > a2 > 0.0
    assert a2 / a1 == pytest.approx(math.exp(-2 * c * 0.1), rel=1e-9)
    assert coefficient(1e6, c) == 0.0  # below 1e-300: 0, no overflow


@pytest.mark.parametrize("u", [math.inf, -math.inf, math.nan])
def test_no_valid_uncertainty_means_no_trust(u):
    assert coefficient(u, 1.0) == 0.0


def test_finite_negatives_are_rounding_noise_of_a_nonnegative_measure():
    assert coefficient(-1e-17, 2.0) == coefficient(-0.1, 2.0) == coefficient(0.0, 2.0) == 1.0


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan])
def test_saturation_needs_a_positive_threshold(bad):
    with pytest.raises(ValueError, match="Invalid uncertainty threshold"):
        saturation(bad)
