"""χ² quantiles and incomplete gamma functions from ``math`` alone, against scipy.special."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import gammainc, gammaincc, gammaincinv

from posegraph.robust.chi_square import chi2_quantile, regularized_gammas
from posegraph.robust.kernels import default_width

QUANTILES = [1e-12, 1e-9, 1e-4, 0.01, 0.1, 0.5, 0.9, 0.99, 0.999, 0.999999, 1 - 1e-9, 1 - 1e-12]
DOFS = [*range(1, 41), 0.5, 2.5, 100, 333, 1000, 6000, 100_000]


@pytest.mark.parametrize("dof", DOFS)
def test_quantiles_equal_scipys_to_1e_11(dof):
    """Both tails to their last digits: the upper quantiles are roots of (1 − q) − Q, not of
    P − q, whose difference from 1 would keep 4 digits at 1 − 1e-12."""
    for quantile in QUANTILES:
        expected = 2.0 * gammaincinv(0.5 * dof, quantile)
        assert chi2_quantile(dof, quantile) == pytest.approx(expected, rel=1e-11, abs=0)


def test_the_ends_and_the_widths():
    assert chi2_quantile(3, 0.0) == 0.0 and chi2_quantile(3, 1.0) == math.inf
    assert chi2_quantile(0, 0.99) == 0.0
    assert default_width(3, 0.999) == pytest.approx(math.sqrt(16.26623619623813), rel=1e-13)
    assert default_width(1, 0.99) == pytest.approx(2.5758293035489004, rel=1e-13)


@pytest.mark.parametrize("a", [0.5, 1.0, 3.0, 10.0, 100.0, 5000.0])
def test_incomplete_gammas_equal_scipys_on_both_sides_of_a_plus_1(a):
    """To 1e-10: at a = 5000 the exponent a log x − x − log Γ(a) is near 4e4, whose last bit
    is 7e-12 of the result."""
    for x in (1e-3, 0.5, a, a + 1.0, 3.0 * a + 5.0):
        lower, upper = regularized_gammas(a, x)
        np.testing.assert_allclose([lower, upper], [gammainc(a, x), gammaincc(a, x)], rtol=1e-10)
