"""Quantiles and confidence intervals of the aggregates (``scipy.stats``).

Means get a two-sided Student-t interval, ``mean +/- t_{(1+c)/2, n-1} * s / sqrt(n)``; rates
(fractions of episodes) a Wilson score interval. Across training seeds, the interquartile mean
with a stratified percentile bootstrap interval (the statistics of ``rliable``, Agarwal et al.
2021, through :func:`scipy.stats.bootstrap`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

__all__ = [
    "MET",
    "NOT_MET",
    "NOT_SHOWN",
    "NO_WORSE_MARGIN",
    "VERDICT_LEGEND",
    "check_probability",
    "episodes_behind",
    "iqm",
    "limit_verdict",
    "no_worse_rate",
    "normal_quantile",
    "rate_verdict",
    "stated_rate_verdict",
    "stratified_bootstrap_iqm",
    "t_interval",
    "t_quantile",
    "weakest_verdict",
    "wilson_interval",
]


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


def _bounds(name: str, stats: Mapping[str, float], *keys: str) -> tuple[float, ...]:
    """The numeric, non-NaN values of ``keys`` in ``stats``; ValueError naming ``name``."""
    try:
        vals = tuple(float(stats[k]) for k in keys)
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{name}: both need numeric {' and '.join(keys)}") from None
    if any(math.isnan(v) for v in vals):
        raise ValueError(f"{name}: an interval bound or rate is NaN {vals}")
    return vals


def no_worse_rate(policy: Mapping[str, float], reference: Mapping[str, float]) -> bool:
    """Whether the data leave the policy's rate possibly no worse than the reference's.

    The two 95 % intervals overlap, or the policy's lies below: the policy's lower bound is
    at most the reference's upper bound. This only says the policy is **not shown worse**;
    wide intervals (few episodes) always pass it, so it is not a verdict that a target is
    met. Its negation is the "not met" of :func:`rate_verdict`, the rule reports judge
    their "no worse than the APF" targets by.

    Args:
        policy: The policy's interval (``ci_low``, ``ci_high``: a Wilson interval, or a
            bootstrap interval across seeds).
        reference: The reference's interval, the same keys.

    Returns:
        Whether the policy's rate is not shown worse than the reference's.

    Raises:
        ValueError: An interval without ``ci_low`` / ``ci_high`` or with a NaN bound.
    """
    try:
        low, high = float(policy["ci_low"]), float(reference["ci_high"])
    except (KeyError, TypeError, ValueError):
        raise ValueError("no_worse_rate: both need numeric ci_low and ci_high") from None
    if math.isnan(low) or math.isnan(high):
        raise ValueError(f"no_worse_rate: an interval bound is NaN ({low}, {high})")
    return low <= high


#: Non-inferiority margin of :func:`rate_verdict`: a rate up to this much (a fraction, here
#: 10 percentage points) above the reference's still counts as "no worse".
NO_WORSE_MARGIN = 0.10

#: The three verdicts of a target.
MET, NOT_MET, NOT_SHOWN = "met", "not met", "not shown"


def rate_verdict(
    policy: Mapping[str, float],
    reference: Mapping[str, float],
    margin: float = NO_WORSE_MARGIN,
) -> str:
    """The verdict on "the policy's rate is no worse than the reference's" (e.g. the APF's).

    Read from each side's rate (``rate``, else ``mean``) and its 95 % interval (``ci_low``,
    ``ci_high``):

    * ``"not met"``: the policy's interval lies wholly above the reference's (its lower
      bound above the reference's upper bound): the policy is worse;
    * ``"met"``: the policy's rate is at most the reference's **and** its interval's upper
      bound at most the reference's rate plus ``margin``: the data rule out the policy
      being more than ``margin`` worse (with no event in either, 0 of n against 0 of n,
      the Wilson upper bound is ``z^2 / (n + z^2)``: 35 episodes at the 10-point margin);
    * ``"not shown"``: anything else: the point estimate is worse but the intervals
      overlap, or the policy's interval is too wide to rule out a rate more than
      ``margin`` above the reference's. Too few episodes never give "met".

    Args:
        policy: The policy's aggregate (a Wilson interval, or a bootstrap one across seeds).
        reference: The reference's, the same keys.
        margin: The non-inferiority margin (a rate difference, ``>= 0``).

    Returns:
        ``"met"``, ``"not met"`` or ``"not shown"``.

    Raises:
        ValueError: A missing or NaN rate or bound, or a negative margin.
    """
    margin = float(margin)
    if not margin >= 0.0:
        raise ValueError(f"margin: must be >= 0, got {margin}")
    if not no_worse_rate(policy, reference):
        return NOT_MET
    key = "rate" if "rate" in policy and "rate" in reference else "mean"
    p_rate, p_high = _bounds("rate_verdict", policy, key, "ci_high")
    (r_rate,) = _bounds("rate_verdict", reference, key)
    if p_rate <= r_rate and p_high <= r_rate + margin:
        return MET
    return NOT_SHOWN


#: What each verdict of :func:`rate_verdict` means, as the reports print it above their targets.
VERDICT_LEGEND = (
    "Met: the policy's rate is no higher than the APF's and its 95 % interval rules out "
    f"a rate more than {100 * NO_WORSE_MARGIN:g} percentage points above it; not met: the "
    "interval lies wholly above the APF's; not shown: neither (too few episodes to decide). "
    "A target with a fixed limit is met when the whole 95 % interval is within it, not met "
    "when the whole interval is beyond it, and not shown otherwise."
)


def limit_verdict(
    stats: Mapping[str, float], limit: float, key: str = "rate", at_most: bool = True
) -> str:
    """The verdict on a fixed limit ("at most 5 % collisions"), read off the 95 % interval.

    * ``"met"``: the whole interval is within the limit (``ci_high <= limit`` for an upper
      limit), so the data rule out missing it;
    * ``"not met"``: the whole interval is beyond it (``ci_low > limit``);
    * ``"not shown"``: the interval straddles the limit, whatever the point estimate: a wide
      interval never gives "met".

    Args:
        stats: The aggregate: the estimate under ``key`` and ``ci_low``, ``ci_high``.
        limit: The limit, in the estimate's units.
        key: The estimate's key (``rate``, ``mean`` or ``iqm``).
        at_most: True for an upper limit (the usual), False for a lower one.

    Returns:
        ``"met"``, ``"not met"`` or ``"not shown"``.

    Raises:
        ValueError: A missing or NaN estimate or bound, or a NaN limit.
    """
    limit = float(limit)
    if limit != limit:
        raise ValueError("limit_verdict: limit: must be a number, got nan")
    _, low, high = _bounds("limit_verdict", stats, key, "ci_low", "ci_high")
    if not at_most:
        low, high, limit = -high, -low, -limit
    if high <= limit:
        return MET
    if low > limit:
        return NOT_MET
    return NOT_SHOWN


def stated_rate_verdict(
    policy: Mapping[str, float],
    reference: Mapping[str, float],
    margin: float = NO_WORSE_MARGIN,
) -> str:
    """:func:`rate_verdict` followed by the episodes behind it: ``"met (500 vs 500 episodes)"``."""
    return f"{rate_verdict(policy, reference, margin)} ({episodes_behind(policy, reference)})"


def episodes_behind(policy: Mapping[str, float], reference: Mapping[str, float]) -> str:
    """``"500 vs 500 episodes"``: each side's ``n_valid`` (else ``n``; ``?`` without either)."""
    counts = [side.get("n_valid", side.get("n")) for side in (policy, reference)]
    shown = [str(int(c)) if c is not None else "?" for c in counts]
    return f"{shown[0]} vs {shown[1]} episodes"


def weakest_verdict(verdicts: Iterable[str]) -> str:
    """The verdict on "every one of them": ``not met`` if any is, else ``not shown`` if any is.

    Raises:
        ValueError: No verdict, or one that is not ``met`` / ``not met`` / ``not shown``.
    """
    order = (NOT_MET, NOT_SHOWN, MET)
    verdicts = list(verdicts)
    if not verdicts or any(v not in order for v in verdicts):
        raise ValueError(f"verdicts: need one or more of {order}, got {verdicts}")
    return min(verdicts, key=order.index)


def iqm(values: ArrayLike) -> float:
    """Interquartile mean: the mean of the middle 50 % (``scipy.stats.trim_mean(x, 0.25)``).

    NaNs are ignored; NaN when no finite value is left.
    """
    arr = np.asarray(values, dtype=np.float64).ravel()
    arr = arr[np.isfinite(arr)]
    return float(stats.trim_mean(arr, 0.25)) if arr.size else math.nan


def stratified_bootstrap_iqm(
    scores: ArrayLike,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """IQM of ``(runs, tasks)`` scores and its stratified bootstrap interval.

    As ``rliable``: the runs (training seeds) are resampled with replacement independently
    within each task (a stratum: here a scenario family), the IQM is taken over the whole
    resampled matrix, and the interval is the percentile interval of those IQMs. Each column
    is one sample of :func:`scipy.stats.bootstrap` (independent resampling per sample).

    Args:
        scores: ``(n_runs, n_tasks)`` (or ``(n_runs,)``: one task) finite scores.
        confidence: Confidence level in (0, 1).
        n_resamples: Bootstrap resamples.
        seed: Seed of the resampling generator.

    Returns:
        ``(iqm, low, high)``; the interval is ``(iqm, iqm)`` with a single run.

    Raises:
        ValueError: For an empty or non-finite score matrix.
    """
    confidence = check_probability("confidence", confidence)
    arr = np.asarray(scores, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.size == 0 or not np.isfinite(arr).all():
        raise ValueError(f"scores: need a finite (runs, tasks) matrix, got shape {arr.shape}")
    point = iqm(arr)
    if arr.shape[0] < 2 or np.ptp(arr, axis=0).max() == 0.0:
        return point, point, point  # nothing to resample: every draw gives the same IQM

    def statistic(*columns: np.ndarray, axis: int = -1) -> np.ndarray:
        return stats.trim_mean(np.concatenate(columns, axis=axis), 0.25, axis=axis)

    res = stats.bootstrap(
        tuple(arr.T),
        statistic,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        paired=False,
        vectorized=True,
        rng=np.random.default_rng(seed),
    )
    ci = res.confidence_interval
    return point, float(ci.low), float(ci.high)
