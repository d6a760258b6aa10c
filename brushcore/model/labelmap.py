"""Checks of a label map (pillar index per element, -1 outside) that every layout shares."""

from __future__ import annotations

import numpy as np

from brushcore.validation import ParameterError


def touching_pillars(labels: np.ndarray, limit: int = 5) -> list[tuple[int, int, int, int]]:
    """Pairs of different pillars sharing an element edge (4-neighbour adjacency).

    Returns
    -------
    Up to ``limit`` tuples (p, q, row, column): pillars p < q touch at the
    element (row, column) of p and its neighbour below or to the right.
    """
    found: list[tuple[int, int, int, int]] = []
    for axis in (0, 1):
        a = labels[:-1, :] if axis == 0 else labels[:, :-1]
        b = labels[1:, :] if axis == 0 else labels[:, 1:]
        rows, cols = np.nonzero((a >= 0) & (b >= 0) & (a != b))
        for r, c in zip(rows[:limit], cols[:limit]):
            p, q = sorted((int(a[r, c]), int(b[r, c])))
            found.append((p, q, int(r), int(c)))
    return sorted(found)[:limit]


def count_touching_pairs(labels: np.ndarray) -> int:
    """How many pairs of different pillars share at least one element edge
    (4-neighbour adjacency; a shared corner does not count)."""
    keys = []
    for a, b in ((labels[:-1, :], labels[1:, :]), (labels[:, :-1], labels[:, 1:])):
        touch = (a >= 0) & (b >= 0) & (a != b)
        lo, hi = np.minimum(a[touch], b[touch]), np.maximum(a[touch], b[touch])
        keys.append(lo.astype(np.int64) * (int(labels.max()) + 1) + hi)
    return int(np.unique(np.concatenate(keys)).size)


def check_not_touching(labels: np.ndarray, name: str, value: object) -> None:
    """Refuse a label map whose pillars touch, naming pillars and elements.

    Raises
    ------
    ParameterError
        For parameter ``name`` (the layout's input) if any two pillars
        share an element edge.
    """
    pairs = touching_pillars(labels)
    if pairs:
        where = "; ".join(f"pillars {p} and {q} at element (row {r}, column {c})"
                          for p, q, r, c in pairs)
        raise ParameterError(name, value, "a layout whose pillars are at least one element "
                             "apart (no shared element edge)", f"{where}")
