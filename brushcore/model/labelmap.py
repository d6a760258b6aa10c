"""Checks of a label map (pillar index per element, -1 outside) that every layout shares."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from brushcore.validation import ParameterError


def pillar_element_counts(labels: np.ndarray, n_pillars: int = 0) -> np.ndarray:
    """Elements of each pillar, indexed by label (at least ``n_pillars``
    entries: a pillar without an element counts 0)."""
    return np.bincount(labels[labels >= 0], minlength=n_pillars)


def _edge_neighbours(labels: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per axis, the element pairs (a, b) that share an edge, b below or to
    the right of a, and where both are of different pillars."""
    for a, b in ((labels[:-1, :], labels[1:, :]), (labels[:, :-1], labels[:, 1:])):
        yield a, b, (a >= 0) & (b >= 0) & (a != b)


def touching_pillars(labels: np.ndarray, limit: int = 5) -> list[tuple[int, int, int, int]]:
    """Pairs of different pillars sharing an element edge (4-neighbour adjacency).

    Returns
    -------
    Up to ``limit`` tuples (p, q, row, column), one per pair: pillars p < q
    touch at the element (row, column) and its neighbour below or to the
    right (the first such element of the pair).
    """
    parts = [(np.minimum(a[touch], b[touch]), np.maximum(a[touch], b[touch]), *np.nonzero(touch))
             for a, b, touch in _edge_neighbours(labels)]
    p, q, rows, cols = (np.concatenate([part[i] for part in parts]) for i in range(4))
    order = np.lexsort((cols, rows, q, p))  # by pair, then by element
    p, q, rows, cols = p[order], q[order], rows[order], cols[order]
    first = np.flatnonzero(np.r_[p.size > 0, (p[1:] != p[:-1]) | (q[1:] != q[:-1])])[:limit]
    return [(int(p[i]), int(q[i]), int(rows[i]), int(cols[i])) for i in first]


def count_touching_pairs(labels: np.ndarray) -> int:
    """How many pairs of different pillars share at least one element edge
    (4-neighbour adjacency; a shared corner does not count)."""
    stride = int(labels.max()) + 1  # a pair (p, q), p < q, as the key p * stride + q
    keys = [np.minimum(a[touch], b[touch]).astype(np.int64) * stride
            + np.maximum(a[touch], b[touch]) for a, b, touch in _edge_neighbours(labels)]
    return int(np.unique(np.concatenate(keys)).size)


def touching_note(pairs: int) -> str:
    """What a run says of `count_touching_pairs` (the command's discretisation
    line, a workflow job's log): "" for none."""
    if not pairs:
        return ""
    return (f"{pairs} pillar pair{'s' * (pairs != 1)} share{'s' * (pairs == 1)} an element "
            "edge (their gap is under an element on this grid; a finer grid separates them)")


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
        raise ParameterError(name, value, "pillars at least one element apart (no shared "
                             "element edge)", f"{where}")
