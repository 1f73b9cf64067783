"""Rates with their intervals and paired comparisons, for outcomes counted over trials.

A claim of the evaluation is a rate: ``k`` of ``n`` trials walked, with its 95 % Wilson score
interval (Wilson 1927; it keeps inside [0, 1] and holds its coverage at small ``n`` and at
rates near 0 or 1, where the normal approximation does not). Two controllers walked on the
same trials are compared by McNemar's exact test: only the trials where they differ count,
and under "no difference" each of those goes either way with probability 1/2 (a two-sided
binomial test on the discordant pairs)."""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Sequence

import numpy as np

Z95 = 1.959963984540054
"""The standard normal's 97.5 % quantile: a two-sided 95 % interval."""


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a rate ``k`` / ``n`` (default 95 %); (0, 1) when ``n`` is 0."""
    if not (isinstance(k, int) and isinstance(n, int) and 0 <= k <= n):
        raise ValueError(f"a rate needs whole numbers 0 <= k <= n, got k={k!r}, n={n!r}")
    if n == 0:
        return 0.0, 1.0
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def rate(outcomes: Sequence[bool]) -> dict:
    """``{"k", "n", "rate", "ci95": [low, high]}`` of trials that succeeded."""
    k, n = sum(bool(o) for o in outcomes), len(outcomes)
    low, high = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n if n else None, "ci95": [low, high]}


def mcnemar_exact(a: Sequence[bool], b: Sequence[bool]) -> dict:
    """McNemar's exact test of two controllers on the same trials (``a[i]``, ``b[i]``: trial
    ``i`` succeeded): ``{"only_a", "only_b", "p_value"}``, the trials only one of them passed
    and the two-sided p-value (1 when they never differ)."""
    if len(a) != len(b):
        raise ValueError(f"a paired test needs the same trials: {len(a)} against {len(b)} outcomes")
    only_a = sum(bool(x) and not bool(y) for x, y in zip(a, b))
    only_b = sum(bool(y) and not bool(x) for x, y in zip(a, b))
    n = only_a + only_b
    if n == 0:
        return {"only_a": 0, "only_b": 0, "p_value": 1.0}
    tail = sum(Fraction(math.comb(n, i), 2 ** n) for i in range(min(only_a, only_b) + 1))
    return {"only_a": only_a, "only_b": only_b, "p_value": float(min(Fraction(1), 2 * tail))}


def format_rate(r: dict) -> str:
    """``k/n [low-high %]``: a rate and its 95 % interval, as the report and README print it."""
    low, high = r["ci95"]
    return f"{r['k']}/{r['n']} [{100 * low:.0f}-{100 * high:.0f} %]"


def iqm(values: Sequence[float]) -> float:
    """The interquartile mean (rliable, Agarwal et al. 2021): the mean of the middle half of the
    sorted values, a value straddling a quartile weighted by the fraction of it inside (3 values:
    weights 1/4, 1, 1/4 over 1.5). ``ValueError`` for none."""
    xs = sorted(float(v) for v in values)
    n = len(xs)
    if n == 0:
        raise ValueError("the IQM of no values")
    lo, hi = n / 4.0, 3.0 * n / 4.0  # the middle half as a stretch of [0, n) on the sorted values
    total = sum(x * max(0.0, min(i + 1, hi) - max(i, lo)) for i, x in enumerate(xs))
    return total / (hi - lo)


def bootstrap_interval(values: Sequence[float], statistic=iqm, resamples: int = 10_000, seed: int = 0,
                       level: float = 0.95) -> tuple[float, float]:
    """The percentile bootstrap interval of ``statistic`` over ``values`` (resampled with
    replacement ``resamples`` times from ``seed``: the same interval on every machine)."""
    xs = [float(v) for v in values]
    if not xs:
        raise ValueError("a bootstrap interval of no values")
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, len(xs), size=(resamples, len(xs)))
    stats = sorted(statistic([xs[i] for i in row]) for row in picks)
    tail = (1.0 - level) / 2.0
    return stats[int(math.floor(tail * (resamples - 1)))], stats[int(math.ceil((1.0 - tail) * (resamples - 1)))]
