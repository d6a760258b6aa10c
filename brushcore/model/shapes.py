"""Pillar cross-sections: disc, square and ellipse of a given area.

A shape is fixed by its kind, an aspect ratio (ellipse) and an
orientation; its size follows from the pillar area A_p = phi L^2 / N, so
the filling factor keeps its meaning (real pillar area / L^2) for every
shape.  The label map asks a shape which element centres it contains.

Conventions
-----------
- aspect: semi-major / semi-minor axis of an ellipse, >= 1 (1 for disc and
  square).
- orientation [degrees]: angle from the x axis (grid columns) to the
  ellipse's major axis or to a side of the square, counter-clockwise in
  the snapshots (which are drawn with y up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SHAPES = ("disc", "square", "ellipse")


def along_axes(dy: np.ndarray, dx: np.ndarray, orientation: float) -> tuple[np.ndarray,
                                                                          np.ndarray]:
    """Offsets (dy, dx) from a pillar's centre in its own axes (u, v): u along
    the major axis or a side at ``orientation`` [degrees] from x, v across it."""
    t = math.radians(orientation)
    return dx * math.cos(t) + dy * math.sin(t), -dx * math.sin(t) + dy * math.cos(t)


def ellipse_half_extents(a: np.ndarray | float, b: np.ndarray | float,
                         orientation: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Half widths along y and x of the bounding boxes of ellipses [length of a, b].

    Parameters
    ----------
    a, b : semi-major and semi-minor axes [length]
    orientation : angle from the x axis to the major axis [degrees]
    """
    t = np.radians(orientation)
    c, s = np.abs(np.cos(t)), np.abs(np.sin(t))
    # the support function of the rotated ellipse along y and along x
    return np.hypot(a * s, b * c), np.hypot(a * c, b * s)


@dataclass(frozen=True)
class PillarShape:
    """The cross-section of every pillar of a generated layout.

    Parameters
    ----------
    kind : "disc", "square" or "ellipse".
    aspect : semi-major / semi-minor axis of an ellipse, >= 1.
    orientation : angle of the major axis (ellipse) or of a side (square)
        from the x axis [degrees].
    """

    kind: str = "disc"
    aspect: float = 1.0
    orientation: float = 0.0

    def half_axes(self, area: float) -> tuple[float, float]:
        """Semi-axes (a, b) [length]: radius, half side, or the ellipse's semi-axes.

        Parameters
        ----------
        area : pillar cross-section A_p [length^2]
        """
        if self.kind == "disc":
            r = math.sqrt(area / math.pi)
            return r, r
        if self.kind == "square":
            s = 0.5 * math.sqrt(area)
            return s, s
        a = math.sqrt(area * self.aspect / math.pi)  # pi a b = A_p with a = aspect b
        return a, a / self.aspect

    def circumradius(self, area: float) -> float:
        """Radius of the smallest centred disc holding the pillar [length]."""
        a, b = self.half_axes(area)
        return math.hypot(a, b) if self.kind == "square" else a

    def half_extents(self, area: float) -> tuple[float, float]:
        """Half width of the pillar's bounding box along y and x [length]."""
        a, b = self.half_axes(area)
        if self.kind == "square":
            c, s = abs(math.cos(math.radians(self.orientation))), abs(
                math.sin(math.radians(self.orientation)))
            return a * (s + c), a * (c + s)
        hy, hx = ellipse_half_extents(a, b, self.orientation)
        return float(hy), float(hx)

    def contains(self, dy: np.ndarray, dx: np.ndarray, area: float) -> np.ndarray:
        """Whether points at offsets (dy, dx) from the centre lie inside [bool].

        Parameters
        ----------
        dy, dx : offsets along y and x, broadcastable [length]
        area : pillar cross-section A_p [length^2]
        """
        a, b = self.half_axes(area)
        if self.kind == "disc":
            return dy**2 + dx**2 <= a * a
        u, v = along_axes(dy, dx, self.orientation)
        if self.kind == "square":
            return (np.abs(u) <= a) & (np.abs(v) <= b)
        return (u / a) ** 2 + (v / b) ** 2 <= 1.0


def shape_label(kind: str = "disc", aspect: float = 1.0, orientation: float = 0.0) -> str:
    """Short text name of a pillar shape, used in file names and as a sweep coordinate.

    "disc", "square" (orientation 0), "square_30.0", "ellipse2.0_30.0"; floats
    in their shortest exact repr, so that `parse_shape_label` inverts it.

    Parameters
    ----------
    kind : "disc", "square" or "ellipse".
    aspect : semi-major / semi-minor axis (ellipses only).
    orientation : angle of the major axis or a side from the x axis [degrees].
    """
    if kind == "disc":
        return "disc"
    if kind == "square":
        return "square" if float(orientation) == 0.0 else f"square_{float(orientation)!r}"
    return f"ellipse{float(aspect)!r}_{float(orientation)!r}"


def parse_shape_label(label: str) -> dict[str, str | float]:
    """`BrushParams` fields (shape, aspect, orientation) of a `shape_label`."""
    if label == "disc":
        return {"shape": "disc", "aspect": 1.0, "orientation": 0.0}
    if label.startswith("square"):
        angle = label[len("square_"):] or "0.0"
        return {"shape": "square", "aspect": 1.0, "orientation": float(angle)}
    if label.startswith("ellipse"):
        aspect, angle = label[len("ellipse"):].split("_")
        return {"shape": "ellipse", "aspect": float(aspect), "orientation": float(angle)}
    raise ValueError(f"unknown pillar shape label {label!r}")
