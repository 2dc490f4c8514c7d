"""Two-sample comparisons for the paper's claims: a one-sided rank test, Cliff's delta and
its seeded bootstrap confidence interval.

Cliff's delta is ``P(X > Y) - P(X < Y)`` for one draw from each sample: +1 when every x
beats every y, -1 for the opposite, 0 for no tendency. It suits fitness values with many
ties (plateaus at 0, or at a few typical optima) where a difference of means does not.
The interval is a percentile bootstrap that resamples each sample independently with a
generator seeded by the caller, so the same data always give the same interval.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class Comparison:
    """One-sided test that ``x`` tends to exceed ``y``, with effect sizes.

    ``u`` and ``p_value``: Mann-Whitney U of ``x`` against ``y`` (alternative: x greater);
    ``delta``: Cliff's delta of ``x`` over ``y`` and ``ci_low``/``ci_high`` its bootstrap
    interval at ``confidence``; ``median_difference``: median(x) - median(y)."""

    n_x: int
    n_y: int
    u: float
    p_value: float
    delta: float
    ci_low: float
    ci_high: float
    confidence: float
    median_difference: float


def cliffs_delta(x: np.ndarray, y: np.ndarray) -> float:
    """Cliff's delta ``P(X > Y) - P(X < Y)`` over all pairs of ``x`` and ``y``."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.size == 0 or y.size == 0:
        raise ValueError("cliffs_delta needs two non-empty samples")
    y = np.sort(y)
    below = np.searchsorted(y, x, side="left")  # y values < each x
    above = y.size - np.searchsorted(y, x, side="right")  # y values > each x
    return float((below.sum() - above.sum()) / (x.size * y.size))


def bootstrap_delta_ci(
    x: np.ndarray, y: np.ndarray, resamples: int, confidence: float, seed: int
) -> tuple[float, float]:
    """Percentile bootstrap interval of Cliff's delta, resampling ``x`` and ``y``
    independently (``resamples`` times, generator seeded with ``seed``)."""
    result = stats.bootstrap(
        (np.asarray(x, float), np.asarray(y, float)),
        cliffs_delta,
        n_resamples=resamples,
        confidence_level=confidence,
        method="percentile",
        paired=False,
        vectorized=False,
        rng=np.random.default_rng(seed),
    )
    interval = result.confidence_interval
    return float(interval.low), float(interval.high)


def compare_greater(
    x: np.ndarray, y: np.ndarray, resamples: int = 2000, confidence: float = 0.95, seed: int = 0
) -> Comparison:
    """Does ``x`` tend to exceed ``y``? One-sided Mann-Whitney U (ties handled by the
    normal approximation's tie correction, scipy's ``method="auto"``), Cliff's delta with a
    seeded percentile bootstrap interval, and the difference of medians."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    test = stats.mannwhitneyu(x, y, alternative="greater")
    low, high = bootstrap_delta_ci(x, y, resamples, confidence, seed)
    return Comparison(
        n_x=int(x.size),
        n_y=int(y.size),
        u=float(test.statistic),
        p_value=float(test.pvalue),
        delta=cliffs_delta(x, y),
        ci_low=low,
        ci_high=high,
        confidence=confidence,
        median_difference=float(np.median(x) - np.median(y)),
    )
