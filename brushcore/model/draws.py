"""The seeded draws of a rough or graded brush: pillar heights and
stiffnesses from (seed, stream), so that a seed names the same brush on
every grid.  Pure functions of their arguments, used by the parameter
checks (`brushcore.model.params`) and the inputs of a run
(`brushcore.model.rough`)."""

from __future__ import annotations

import math

import numpy as np


def lognormal_kbar(mean: float, cv: float, n: int, seed: int) -> np.ndarray:
    """n lognormal values with the given mean and coefficient of variation."""
    if cv == 0:
        return np.full(n, mean)
    s2 = math.log1p(cv * cv)
    rng = np.random.default_rng([seed, 2])
    return mean * np.exp(rng.normal(-0.5 * s2, math.sqrt(s2), n))


def gaussian_heights(std: float, n: int, seed: int) -> np.ndarray:
    """n heights of zero mean and standard deviation ``std`` (zeros for 0)."""
    if std == 0:
        return np.zeros(n)
    return np.random.default_rng([seed, 1]).normal(0.0, std, n)
