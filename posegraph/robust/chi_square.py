"""Quantiles of the χ² distribution, in Python's ``math`` alone.

χ²_k is Gamma(k/2, scale 2), so its q-quantile is 2x with P(k/2, x) = q, P the regularised lower
incomplete gamma function (Abramowitz & Stegun §26.4.19). P comes from its series below x = a + 1
and its complement Q from the Legendre continued fraction above, evaluated by the modified Lentz
method (Press, Teukolsky, Vetterling & Flannery 2007, "Numerical Recipes", 3rd ed., §6.2 and
§5.2). The quantile is the root of P − q (or of (1 − q) − Q above the median, so that tail
quantiles keep their digits), found by Newton's method kept inside a bracket. scipy.special gives
the same numbers, but importing it costs a command-line start about 0.3 s.
"""

from __future__ import annotations

import functools
import math

_EPSILON = 1e-16
_TINY = 1e-300
_ITERATIONS = 10_000


def _series(a: float, x: float) -> float:
    """P(a, x) by its series, for x < a + 1."""
    term = total = 1.0 / a
    n = a
    while abs(term) > total * _EPSILON:
        n += 1.0
        term *= x / n
        total += term
    return total * math.exp(a * math.log(x) - x - math.lgamma(a))


def _continued_fraction(a: float, x: float) -> float:
    """Q(a, x) by its continued fraction, for x ≥ a + 1 (modified Lentz)."""
    b = x + 1.0 - a
    c, d = 1.0 / _TINY, 1.0 / b
    fraction = d
    for i in range(1, _ITERATIONS):
        coefficient = -i * (i - a)
        b += 2.0
        d = coefficient * d + b
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = b + coefficient / c
        c = c if abs(c) > _TINY else _TINY
        fraction *= d * c
        if abs(d * c - 1.0) < _EPSILON:
            break
    return fraction * math.exp(a * math.log(x) - x - math.lgamma(a))


def regularized_gammas(a: float, x: float) -> tuple[float, float]:
    """(P(a, x), Q(a, x)) = the regularised lower and upper incomplete gamma functions, a > 0."""
    if x <= 0.0:
        return 0.0, 1.0
    if x < a + 1.0:
        lower = _series(a, x)
        return lower, 1.0 - lower
    upper = _continued_fraction(a, x)
    return 1.0 - upper, upper


@functools.lru_cache(maxsize=1024)
def chi2_quantile(dof: float, quantile: float) -> float:
    """The ``quantile`` of χ² with ``dof`` degrees of freedom (0 at 0, ∞ at 1; 0 for no
    degrees of freedom, where χ² is 0). Remembered: a stream asks for the same few again at
    every call."""
    if quantile <= 0.0 or dof <= 0:
        return 0.0
    if quantile >= 1.0:
        return math.inf
    a, upper_tail = 0.5 * dof, quantile > 0.5

    def excess(x: float) -> float:  # increasing in x, zero at the quantile
        lower, upper = regularized_gammas(a, x)
        return (1.0 - quantile) - upper if upper_tail else lower - quantile

    x, low, high = max(a, 1e-300), 0.0, math.inf
    for _ in range(_ITERATIONS):
        value = excess(x)
        if value == 0.0:
            break
        low, high = (x, high) if value < 0.0 else (low, x)
        density = math.exp((a - 1.0) * math.log(x) - x - math.lgamma(a))
        step = x - value / density if density > 0.0 else math.nan
        if not low < step < high:  # Newton left the bracket: bisect it (or grow it)
            step = 0.5 * (low + high) if math.isfinite(high) else 2.0 * x
        if abs(step - x) <= 1e-15 * x:
            x = step
            break
        x = step
    return 2.0 * x
