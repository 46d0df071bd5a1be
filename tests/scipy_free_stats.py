"""Tail probabilities for chi-square and normal tests, without SciPy."""
import math


def chi2_sf(x, k):
    """P(X > x) for X ~ chi-square with k degrees of freedom (Wilson-Hilferty; accurate to
    a few percent of the p-value for k >= 10, enough for thresholds like 1e-4)."""
    if x <= 0:
        return 1.0
    z = ((x / k) ** (1 / 3) - (1 - 2 / (9 * k))) / math.sqrt(2 / (9 * k))
    return 0.5 * math.erfc(z / math.sqrt(2))


def normal_two_sided_p(z):
    return math.erfc(abs(z) / math.sqrt(2))
