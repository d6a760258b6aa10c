"""Frozen parameter sets and their validation, done once at the edge.

`BrushParams` describes the physical problem, `SolverOptions` the numerics.
Both validate in ``__post_init__`` so that a bad value fails with a message
naming the parameter and its allowed range before any computation starts.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from .lattices import HEX_ASPECT_TOLERANCE, hexagonal_lattice, nearest_hexagonal_counts
from .shapes import SHAPES
from .theory import stiffness_from_kbar

LAYOUTS = ("regular", "random", "hexagonal", "file")
#: Largest ellipse aspect ratio: beyond it the minor axis of a pillar that
#: passes the radius rule (on its equal-area radius) spans under an element.
MAX_ASPECT = 10.0


class ParameterError(ValueError):
    """A parameter is outside its allowed range; the message names both.

    Attributes
    ----------
    name : the parameter's name in the Python API (``n_pillars``)
    value : the value given
    allowed : what would be accepted
    reason : why the value fails, where more than "out of range" (may be "")

    `in_terms_of` renders the same error in another vocabulary (the CLI's
    flags, the workflow's config keys), so that users read the name they
    typed.
    """

    def __init__(self, name: str, value: object, allowed: str, reason: str = "") -> None:
        self.name, self.value, self.allowed, self.reason = name, value, allowed, reason
        super().__init__(self.in_terms_of({}))

    def in_terms_of(self, names: Mapping[str, str], sep: str = "=") -> str:
        """The message with ``name`` replaced by ``names[name]`` (if present)."""
        label = names.get(self.name, self.name)

        def translate(text: str) -> str:
            for api, user in names.items():
                text = re.sub(rf"(?<![\w-]){re.escape(api)}(?![\w-])", user, text)
            return text

        reason = f" ({translate(self.reason)})" if self.reason else ""
        value = self.value if isinstance(self.value, str) and sep != "=" else repr(self.value)
        return f"{label}{sep}{value} is invalid{reason}: allowed {translate(self.allowed)}"


#: The discretisation rule (issue 16): a pillar radius of at least this many
#: elements and a realised filling factor within this relative error of the
#: requested one, unless the caller asks for a coarse run explicitly.  The
#: paper's finest brush (2304 pillars on 512^2: radius 2.08 elements, phi
#: realised 0.117 for 0.12, -2.3 %) passes; 256 pillars on 64^2 (radius
#: 0.78, phi 0.25) does not.
MIN_RADIUS_ELEMENTS = 2.0
MAX_PHI_ERROR = 0.05
#: Floor even for explicitly coarse runs: a disc of radius >= sqrt(2)/2
#: elements contains an element centre wherever it lies, so every pillar
#: keeps at least one element.
FLOOR_RADIUS_ELEMENTS = math.sqrt(0.5)


def _require(ok: bool, name: str, value: object, allowed: str, reason: str = "") -> None:
    if not ok:
        raise ParameterError(name, value, allowed, reason)


def _is_real(value: object) -> bool:
    """Python and NumPy reals (np.float32, np.int64, ...), not booleans."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _is_integer(value: object) -> bool:
    """Python and NumPy integers, not booleans."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def _normalise(obj: object, integers: tuple[str, ...], reals: tuple[str, ...]) -> None:
    """Turn NumPy scalars of a frozen dataclass into Python int / float in place.

    Users loop over ``np.array([64, 128])``; the checks and the netCDF
    attributes want plain Python numbers.  Anything else is left for the
    range checks to refuse.
    """
    for name in integers:
        value = getattr(obj, name)
        if _is_integer(value):
            object.__setattr__(obj, name, int(value))
    for name in reals:
        value = getattr(obj, name)
        if _is_real(value):
            object.__setattr__(obj, name, float(value))


@dataclass(frozen=True)
class BrushParams:
    """One pull-off problem: a brush of equal pillars on equal springs.

    Parameters
    ----------
    layout : "regular" (sqrt(N) x sqrt(N) lattice), "random" (random
        sequential addition of equal pillars), "hexagonal" (triangular
        lattice of rows x columns = N, see `layout.hexagonal_centres`) or
        "file" (the label map or image in ``layout_file``).
    n_pillars : number of pillars N >= 1 (a perfect square for "regular",
        rows x columns near the hexagonal aspect for "hexagonal", the
        file's count for "file").
    kbar : normalised spring stiffness k / (E* L) in (0, inf]; inf = rigid.
    grid : elements per side n of the square L x L holding the pillars.
    phi : requested filling factor (total pillar area / L^2) in (0, 0.5].
    seed : seed of numpy's Generator for "random" (ignored for "regular").
    min_gap : minimum gap between pillar edges for "random" [elements], >= 1.
    e_star : effective modulus E* [stress].
    dgamma : work of adhesion [energy / area].
    h : element size [length].
    allow_coarse : run even when the grid resolves the pillars poorly (a
        pillar radius under MIN_RADIUS_ELEMENTS elements, or a realised
        filling factor more than MAX_PHI_ERROR off the requested one);
        such runs are refused by default.
    shape : pillar cross-section of generated layouts, "disc" (default),
        "square" or "ellipse"; each pillar has the area phi L^2 / N, so
        ``pillar_radius`` is the equal-area radius for every shape.
    aspect : semi-major / semi-minor axis of an ellipse in [1, MAX_ASPECT]
        (1 for other shapes).
    orientation : angle from the x axis to the major axis of an ellipse or
        a side of a square [degrees] (0 for discs).
    layout_file : path of the ``.npy`` label map or ``.png`` image of a
        "file" layout ("" otherwise).  Its n_pillars, grid and phi must be
        the file's; `layout_file.file_params` fills them in.

    Integer and real parameters accept NumPy scalars and are stored as
    Python ``int`` / ``float``.  Dimensional parameters are in one
    consistent unit system; curve files state SI (E* in Pa, dgamma in
    J m-2, h in m), so the defaults describe a run in units E* = dgamma =
    h = 1.
    """

    layout: str
    n_pillars: int
    kbar: float
    grid: int
    phi: float = 0.12
    seed: int = 0
    min_gap: float = 1.0
    e_star: float = 1.0
    dgamma: float = 1.0
    h: float = 1.0
    allow_coarse: bool = False
    shape: str = "disc"
    aspect: float = 1.0
    orientation: float = 0.0
    layout_file: str = ""

    def __post_init__(self) -> None:
        _normalise(self, ("n_pillars", "grid", "seed"),
                   ("kbar", "phi", "min_gap", "e_star", "dgamma", "h", "aspect",
                    "orientation"))
        _require(self.layout in LAYOUTS, "layout", self.layout, f"one of {LAYOUTS}")
        _require(_is_integer(self.n_pillars) and self.n_pillars >= 1,
                 "n_pillars", self.n_pillars, "an integer N >= 1")
        if self.layout == "regular":
            side = math.isqrt(self.n_pillars)
            _require(side * side == self.n_pillars, "n_pillars", self.n_pillars,
                     "a perfect square (1, 4, 9, 16, ...) for regular brushes")
        if self.layout == "hexagonal" and hexagonal_lattice(self.n_pillars) is None:
            lower, upper = nearest_hexagonal_counts(self.n_pillars)
            _require(False, "n_pillars", self.n_pillars,
                     "a count that fills a hexagonal lattice, e.g. "
                     + (f"{lower} or {upper}" if lower else f"{upper}"),
                     f"a hexagonal lattice needs rows x columns = N with rows/columns within "
                     f"a factor {HEX_ASPECT_TOLERANCE:g} of 2/sqrt(3)")
        self._check_shape()
        _require(_is_real(self.kbar) and not math.isnan(self.kbar) and self.kbar > 0,
                 "kbar", self.kbar, "a number in (0, inf]; inf means rigid pillars")
        _require(_is_integer(self.grid) and 4 <= self.grid <= 8192, "grid", self.grid,
                 "an integer in [4, 8192]")
        _require(_is_real(self.phi) and 0.0 < self.phi <= 0.5, "phi", self.phi,
                 "a number in (0, 0.5]")
        _require(_is_integer(self.seed) and self.seed >= 0, "seed", self.seed,
                 "an integer >= 0")
        _require(_is_real(self.min_gap) and 1.0 <= self.min_gap < self.grid,
                 "min_gap", self.min_gap, f"a number of elements in [1, {self.grid})")
        for name in ("e_star", "dgamma", "h"):
            value = getattr(self, name)
            _require(_is_real(value) and math.isfinite(value) and value > 0, name, value,
                     "a finite number > 0")
        _require(isinstance(self.allow_coarse, (bool, np.bool_)), "allow_coarse",
                 self.allow_coarse, "True or False")
        object.__setattr__(self, "allow_coarse", bool(self.allow_coarse))
        r = self.pillar_radius_elements
        floor = FLOOR_RADIUS_ELEMENTS if self.allow_coarse else MIN_RADIUS_ELEMENTS
        _require(r >= floor, "grid", self.grid,
                 f"grid >= {math.ceil(floor * self.grid / r)}"
                 + ("" if self.allow_coarse else " (or allow_coarse to run it anyway)"),
                 f"a pillar radius spans {r:.3g} elements, under the {floor:.3g} "
                 + ("that cover an element centre" if self.allow_coarse else
                    "needed for a meaningful detachment criterion"))

    def _check_shape(self) -> None:
        """Validate shape, aspect, orientation and layout_file (after the layout)."""
        if not isinstance(self.layout_file, str) and hasattr(self.layout_file, "__fspath__"):
            object.__setattr__(self, "layout_file", str(self.layout_file))
        _require(isinstance(self.layout_file, str), "layout_file", self.layout_file,
                 "a path (str or os.PathLike)")
        if self.layout == "file":
            _require(self.layout_file != "", "layout_file", self.layout_file,
                     "the path of a .npy label map or .png image for the file layout")
        else:
            _require(self.layout_file == "", "layout_file", self.layout_file,
                     "no layout file unless layout is 'file'")
        _require(self.shape in SHAPES, "shape", self.shape, f"one of {SHAPES}")
        _require(self.layout != "file" or self.shape == "disc", "shape", self.shape,
                 "the default 'disc' for the file layout (its shapes come from the file)")
        _require(_is_real(self.aspect) and 1.0 <= self.aspect <= MAX_ASPECT, "aspect",
                 self.aspect, f"a number in [1, {MAX_ASPECT:g}]")
        _require(self.shape == "ellipse" or self.aspect == 1.0, "aspect", self.aspect,
                 "1 unless shape is 'ellipse'")
        _require(_is_real(self.orientation) and math.isfinite(self.orientation),
                 "orientation", self.orientation, "a finite angle in degrees")
        _require(self.shape in ("square", "ellipse") or self.orientation == 0.0,
                 "orientation", self.orientation, "0 unless shape is 'square' or 'ellipse'")

    @property
    def side(self) -> float:
        """Side L = n h of the square holding the pillars [length]."""
        return self.grid * self.h

    @property
    def pillar_radius(self) -> float:
        """Pillar radius a_p = L sqrt(phi / (pi N)) [length] (equal-area radius)."""
        return self.side * math.sqrt(self.phi / (math.pi * self.n_pillars))

    @property
    def pillar_radius_elements(self) -> float:
        """Pillar radius in elements."""
        return self.pillar_radius / self.h

    @property
    def pillar_area(self) -> float:
        """Cross-section of one pillar A_p = phi L^2 / N [length^2]."""
        return self.phi * self.side**2 / self.n_pillars

    @property
    def stiffness(self) -> float:
        """Spring stiffness k = kbar E* L [force / length] (inf when rigid)."""
        return stiffness_from_kbar(self.kbar, self.e_star, self.side)

    def as_attrs(self) -> dict[str, float | int | str]:
        """All fields as netCDF-safe attributes (inf kept as a float)."""
        return {k: (int(v) if isinstance(v, bool) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class SolverOptions:
    """Numerical options of the pull-off solver.

    Parameters
    ----------
    rtol : CG stops when its error estimate (the preconditioned residual) is
        below rtol times the largest stress, in (0, 1e-3].  The default 1e-4
        moves F_ad and W by < 1e-4 against 1e-8 (measured and tested); use
        `SolverOptions.exact()` for reference results.
    max_iter : CG iterations allowed per solve before failing, >= 1.
    tie_rtol : elements whose stress is within this relative distance of the
        critical stress detach together, so symmetric layouts stay symmetric
        (1e-9 was too tight at kbar = 1e-8, where round-off in the soft
        springs' coarse problem reaches ~1e-10).
    lookahead : extra relative window of the next event whose elements are
        detached in the same batch; 0 (default) is the exact event-driven
        result, > 0 trades accuracy of F_ad and W for fewer solves.
    cascade : "local" (default) or "global" (the paper's algorithm, the
        reference).  Both detach, at fixed d, every element above sigma_c
        and re-solve until none is.  "global" re-solves the whole system
        after every round.  "local" updates each pillar exactly with its own
        block inverse, holding the other pillars' field, and continues
        without a global solve only while a bound on that field's change
        (monopole at closest approach, x30) cannot flip any decision; it
        always re-solves globally before the next event.  Measured against
        "global": F_ad and W within 2e-4 on regular and random brushes, with
        2-4x fewer operator applications for soft brushes.
    """

    rtol: float = 1e-4
    max_iter: int = 5000
    tie_rtol: float = 1e-7
    lookahead: float = 0.0
    cascade: str = "local"

    @classmethod
    def exact(cls) -> "SolverOptions":
        """Reference settings: global cascades, CG to 1e-8."""
        return cls(rtol=1e-8, cascade="global")

    def __post_init__(self) -> None:
        _normalise(self, ("max_iter",), ("rtol", "tie_rtol", "lookahead"))
        _require(_is_real(self.rtol) and 0 < self.rtol <= 1e-3, "rtol", self.rtol,
                 "a number in (0, 1e-3]")
        _require(_is_integer(self.max_iter) and self.max_iter >= 1, "max_iter",
                 self.max_iter, "an integer >= 1")
        _require(_is_real(self.tie_rtol) and 0 <= self.tie_rtol <= 1e-6, "tie_rtol",
                 self.tie_rtol, "a number in [0, 1e-6]")
        _require(_is_real(self.lookahead) and 0 <= self.lookahead <= 0.1, "lookahead",
                 self.lookahead, "a number in [0, 0.1]")
        _require(self.cascade in ("local", "global"), "cascade", self.cascade,
                 "'local' or 'global'")
