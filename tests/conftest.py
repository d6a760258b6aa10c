"""Shared helpers for the physics tests."""

from __future__ import annotations

import math

import pytest

from brushcore import BrushParams


def punch_params(radius: float, kbar: float = math.inf, **kw) -> BrushParams:
    """One centred circular punch of the given radius [elements] on a snug grid."""
    n = int(math.ceil(2.6 * radius))
    n += n % 2  # even grid: the punch centre sits on an element corner, symmetric footprint
    return BrushParams("regular", 1, kbar, n, phi=math.pi * radius**2 / n**2, **kw)


@pytest.fixture
def punch():
    return punch_params
