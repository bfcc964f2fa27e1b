"""The mean over seeds and its 95 % Student t interval, without scipy.

The project does not depend on scipy for one quantile: the two-sided 95 % critical values
of Student's t are tabulated for 1-30 degrees of freedom (to 9 digits) and come from the
Cornish-Fisher expansion around the normal quantile above 30, where it is accurate to
better than 1e-6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

# t_{0.975}(df) for df = 1..30 (Abramowitz & Stegun 26.10; any statistics package agrees).
_T975 = (
    12.706204736, 4.302652730, 3.182446305, 2.776445105, 2.570581836, 2.446911851,
    2.364624252, 2.306004135, 2.262157163, 2.228138852, 2.200985160, 2.178812830,
    2.160368656, 2.144786688, 2.131449546, 2.119905299, 2.109815578, 2.100922040,
    2.093024054, 2.085963447, 2.079613845, 2.073873068, 2.068657610, 2.063898562,
    2.059538553, 2.055529439, 2.051830516, 2.048407142, 2.045229642, 2.042272456,
)
_Z975 = 1.959963984540054


def t_critical_95(df: int) -> float:
    """Two-sided 95 % critical value of Student's t with ``df`` degrees of freedom."""
    if df < 1:
        raise ValueError(f"degrees of freedom must be at least 1, got {df}")
    if df <= len(_T975):
        return _T975[df - 1]
    z = _Z975
    # Cornish-Fisher terms (Abramowitz & Stegun 26.7.5), in powers of 1/df.
    g1 = (z**3 + z) / 4
    g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96
    g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384
    g4 = (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160
    return z + g1 / df + g2 / df**2 + g3 / df**3 + g4 / df**4


@dataclass(frozen=True)
class Interval:
    """A mean over ``n`` seeds and its 95 % t interval [lo, hi]; lo = hi = nan when n < 2."""

    mean: float
    lo: float
    hi: float
    n: int

    def as_dict(self) -> dict[str, float | int | None]:
        return {"mean": _finite_or_none(self.mean), "lo": _finite_or_none(self.lo),
                "hi": _finite_or_none(self.hi), "n": self.n}


def mean_interval(values: Sequence[float] | np.ndarray) -> Interval:
    """Mean of ``values`` with the 95 % interval mean +- t(n-1) s / sqrt(n)."""
    x = np.asarray(values, dtype=np.float64)
    n = int(x.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0)
    mean = float(x.mean())
    if n < 2:
        return Interval(mean, math.nan, math.nan, n)
    half = t_critical_95(n - 1) * float(x.std(ddof=1)) / math.sqrt(n)
    return Interval(mean, mean - half, mean + half, n)


def _finite_or_none(v: float) -> float | None:
    # JSON has no NaN: an undefined bound is written as null.
    return v if math.isfinite(v) else None


__all__ = ["Interval", "mean_interval", "t_critical_95"]
