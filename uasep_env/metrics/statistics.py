"""Quantiles and confidence intervals of the aggregates (``scipy.stats``).

Means get a two-sided Student-t interval, ``mean +/- t_{(1+c)/2, n-1} * s / sqrt(n)``; rates
(fractions of episodes) a Wilson score interval.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

__all__ = ["check_probability", "normal_quantile", "t_interval", "t_quantile", "wilson_interval"]


def check_probability(name: str, p: float) -> float:
    """Return ``p`` as a float; raise ``ValueError`` naming ``name`` unless ``0 < p < 1``."""
    p = float(p)
    if not 0.0 < p < 1.0:
        raise ValueError(f"{name}: must be in (0, 1), got {p}")
    return p


def normal_quantile(p: float) -> float:
    """Quantile of the standard normal distribution.

    Args:
        p: Probability in (0, 1).

    Returns:
        ``z`` with ``Phi(z) = p``.

    Raises:
        ValueError: If ``p`` is outside (0, 1).
    """
    p = check_probability("p", p)
    return float(stats.norm.ppf(p))


def t_quantile(p: float, df: float) -> float:
    """Quantile of Student's t distribution.

    E.g. ``t_quantile(0.975, 1) = 12.7062047``, ``t_quantile(0.975, 4) = 2.7764451``,
    ``t_quantile(0.975, 29) = 2.0452296``.

    Args:
        p: Probability in (0, 1).
        df: Degrees of freedom, ``> 0`` (non-integer allowed).

    Returns:
        ``t`` with ``P(T <= t) = p``.

    Raises:
        ValueError: If ``p`` is outside (0, 1) or ``df <= 0``.
    """
    p = check_probability("p", p)
    df = float(df)
    if not df > 0.0 or not math.isfinite(df):
        raise ValueError(f"df: must be a finite number > 0, got {df}")
    return float(stats.t.ppf(p, df))


def t_interval(values: ArrayLike, confidence: float = 0.95) -> tuple[float, float]:
    """Student-t confidence interval for the mean of ``values`` (NaNs ignored).

    ``mean +/- t_{(1+confidence)/2, n-1} * s / sqrt(n)`` with ``s`` the sample standard
    deviation (ddof=1) and ``n`` the number of finite values.

    Args:
        values: Sample values.
        confidence: Confidence level in (0, 1).

    Returns:
        ``(low, high)``; ``(NaN, NaN)`` when fewer than two finite values.
    """
    confidence = check_probability("confidence", confidence)
    arr = np.asarray(values, dtype=np.float64).ravel()
    arr = arr[np.isfinite(arr)]
    n = arr.size
    if n < 2:
        return math.nan, math.nan
    mean = float(arr.mean())
    half = t_quantile(0.5 * (1.0 + confidence), n - 1) * float(arr.std(ddof=1)) / math.sqrt(n)
    return mean - half, mean + half


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (without continuity correction).

    ``(p + z^2/(2n) -/+ z sqrt(p(1-p)/n + z^2/(4n^2))) / (1 + z^2/n)`` with ``p = k/n`` and
    ``z`` the normal quantile at ``(1+confidence)/2``. At ``k = 0`` it gives
    ``[0, z^2/(n+z^2)]``, at ``k = n`` ``[n/(n+z^2), 1]``. Computed by
    :meth:`scipy.stats.binomtest`'s ``proportion_ci(method="wilson")``.

    Args:
        successes: Number of successes ``k``, ``0 <= k <= n``.
        n: Number of trials.
        confidence: Confidence level in (0, 1).

    Returns:
        ``(low, high)``; ``(NaN, NaN)`` when ``n == 0``.

    Raises:
        ValueError: If ``successes`` is outside ``[0, n]`` or ``n < 0``.
    """
    confidence = check_probability("confidence", confidence)
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"successes: need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(int(successes), int(n)).proportion_ci(confidence, method="wilson")
    return float(ci.low), float(ci.high)
