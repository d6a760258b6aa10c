"""Frozen parameter sets and their validation, done once at the edge.

`BrushParams` describes the physical problem (the numerics' settings,
`SolverOptions`, live in `brushcore.numerics.options`).  It validates in
``__post_init__`` so that a bad value fails with a message
naming the parameter and its allowed range before any computation starts.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from collections.abc import Mapping
from dataclasses import MISSING, asdict, dataclass, field, fields

import numpy as np

from brushcore.validation import (ParameterError, is_integer, is_one_of, is_real, normalise,
                                  require, require_switches, suggest_keywords)
from brushcore.model.lattices import HEX_ASPECT_TOLERANCE, hexagonal_lattice, nearest_hexagonal_counts
from brushcore.model.shapes import SHAPES
from brushcore.model.draws import lognormal_kbar
from brushcore.model.theory import stiffness_from_kbar
from brushcore.numerics.platform.backend import BACKENDS

LAYOUTS = ("regular", "random", "hexagonal", "file")
#: Largest ellipse aspect ratio: beyond it the minor axis of a pillar that
#: passes the radius rule (on its equal-area radius) spans under an element.
MAX_ASPECT = 10.0
#: Largest |orientation| [degrees]: beyond a turn an angle says nothing more.
MAX_ORIENTATION = 360.0


#: The discretisation rule: a pillar radius of at least this many
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

#: The grid whose element sets a random layout's gap on every grid: the
#: paper's 512 x 512.  A gap of ``min_gap`` elements of the run's own grid
#: would make the layout depend on the mesh (random sequential addition
#: rejects other candidates), so a seed would name another brush on every
#: grid, and a refinement study would compare different brushes; measured
#: before: random 64, 220, 425 and 1620 at 1024^2 left the 512^2 layout at
#: their 31st, 45th, 133rd and 80th pillar.
RANDOM_GAP_GRID = 512

#: Ranges beyond which a run cannot mean anything and fails deep inside the
#: solver (measured 2026-12-05): kbar 1e-14 left CG at 99 % error on random
#: 16 (64^2) and 1e-18 made the pillar blocks singular; below 1e-9 round-off
#: in the soft springs breaks the ties of mirror-image pillars on the whole
#: grid (regular 4 x 4 on 64^2 at 3e-10: W 3.9 % off the quadrant solve,
#: within 1e-5 at 1e-9 on 32^2 to 128^2), so 1e-9 is the floor (the sweep
#: goes down to 1e-6);
#: roughness 1e30 d_K hung the approach (1e3 runs at once, each pillar then
#: separate); e_star, dgamma or h beyond 1e+-100 overflowed.
MIN_KBAR = 1e-9
MIN_GRID, MAX_GRID = 4, 8192
MAX_ROUGH = 1e3  # roughness, |heights| and |gap map| [d_K], preload [F_K]
MAX_KBAR_SPREAD = 100.0  # coefficient of variation
UNIT_RANGE = (1e-30, 1e30)  # e_star, dgamma, h in the inputs' units
MAX_SEED = 2**63 - 1  # a file attribute is an int64
MAX_PHI = 0.5  # filling factor: pillars cover at most half the square


def narrowest_radius(radius: float, shape: str, aspect: float) -> float:
    """Half-width across a pillar's narrowest direction, in the units of its
    equal-area ``radius``: an ellipse's semi-minor axis r / sqrt(aspect), the
    equal-area radius itself for discs and squares (as the radius rule reads it)."""
    return radius / math.sqrt(aspect) if shape == "ellipse" else radius


@suggest_keywords
@dataclass(frozen=True)
class BrushParams:
    """One pull-off problem: a brush of pillars on springs, equal by default,
    with optional heights, per-pillar stiffness, a gap map and a preload.

    Parameters
    ----------
    layout : "regular" (sqrt(N) x sqrt(N) lattice), "random" (random
        sequential addition of equal pillars), "hexagonal" (triangular
        lattice of rows x columns = N, see `layout.hexagonal_centres`) or
        "file" (the label map or image in ``layout_file``).
    n_pillars : number of pillars N >= 1 (a perfect square for "regular",
        rows x columns near the hexagonal aspect for "hexagonal", the
        file's count for "file": `brushcore.file_params` fills it in, with grid
        and phi).
    kbar : normalised spring stiffness k / (E* L) in [1e-9, inf] (`MIN_KBAR`); inf = rigid.
    grid : elements per side n of the square L x L holding the pillars, in
        [4, 8192]; a pillar radius must span at least 2 elements and the
        realised phi lie within 5 % of ``phi`` (checked here and, for the
        filling factor, by `simulate`, which names the next grid that
        passes), unless ``allow_coarse``.
    phi : requested filling factor (total pillar area / L^2) in (0, MAX_PHI].
    seed : seed of numpy's Generator for "random", and for the heights and
        stiffnesses of rough or graded lattices (roughness, kbar_spread);
        ignored for flat lattices; in [0, 2**63 - 1].
    min_gap : minimum gap between pillar edges for "random", in elements
        of the 512 x 512 grid (L / 512 each, whatever ``grid``, so that a
        seed names one brush on every grid), in [1, 512); other layouts
        record 1 (another value is warned of and recorded as 1, as the
        CLI's --min-gap).
    e_star : effective modulus E* [stress], in [1e-30, 1e30] (`UNIT_RANGE`).
    dgamma : work of adhesion [energy / area], in [1e-30, 1e30].
    h : element size [length], in [1e-30, 1e30].
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
    layout_file : path of the ``.npy`` label map, ``.png`` image or ``.csv``
        pillar table of a "file" layout ("" otherwise).  Its n_pillars and
        phi (and a map's or image's grid; a table is drawn on any grid)
        must be the file's; `brushcore.file_params` fills them in.
    roughness : standard deviation S in [0, 1e3] of Gaussian pillar heights, in
        units of d_K = sqrt(2 pi dgamma a0 / E*) (a0 = sqrt(A / pi), A the
        discretised pillar area), drawn from ``seed`` (also for regular
        brushes); 0 (default) is the flat brush.
    preload : compressive force P in [0, 1e3] the approach stops at, in units of
        F_K = sqrt(8 pi E* dgamma a0^3); 0 stops at first touch.
    kbar_spread : coefficient of variation C in [0, 100] of a lognormal per-pillar
        kbar with mean ``kbar`` (finite kbar only), drawn from ``seed``.
    heights : protrusion of each pillar in units of d_K, each in [-1e3, 1e3],
        in label order (see `brushcore.model.layout.regular_centres`; larger reaches the
        substrate first); exclusive with ``roughness``.
    kbar_values : kbar of each pillar in [1e-9, inf], label order; exclusive
        with ``kbar_spread`` (``kbar`` then only names the brush: finite
        where any pillar is, as a sweep files the brush under it).
    gap_map : extra gap of every element, shape (grid, grid), in units of
        d_K, each in [-1e3, 1e3], added below the pillar heights: element
        offset z_i = z_p - gap_i (a spherical tip is r^2 / 2R, a tilt a
        linear ramp).
    backend : where the numbers are crunched, "cpu" (NumPy, default) or
        "gpu" (CuPy; see `brushcore.numerics.platform.backend`).  Not part of the
        problem: excluded from equality, hashing, `as_attrs` and the
        parameter hash, so a curve's identity does not depend on where it
        ran.  Only the name is checked here; CuPy and the card are checked
        by `simulate` before any work.

    Arrays are copied, stored read-only, and compared through their digest
    (``inputs_digest``), so equal parameters compare and hash equal.  A
    pickled copy is built through the constructor again (validated, arrays
    read-only).

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

    roughness: float = 0.0
    preload: float = 0.0
    kbar_spread: float = 0.0
    heights: np.ndarray | None = field(default=None, compare=False, repr=False)
    kbar_values: np.ndarray | None = field(default=None, compare=False, repr=False)
    gap_map: np.ndarray | None = field(default=None, compare=False, repr=False)
    inputs_digest: str = field(default="", init=False)
    backend: str = field(default="cpu", compare=False)

    def __post_init__(self) -> None:
        normalise(self, ("n_pillars", "grid", "seed"),
                   ("kbar", "phi", "min_gap", "e_star", "dgamma", "h", "aspect",
                    "orientation", "roughness", "preload", "kbar_spread"),
                  ("layout", "shape", "backend", "layout_file"))
        require(is_one_of(self.layout, LAYOUTS), "layout", self.layout, f"one of {LAYOUTS}")
        require(is_integer(self.n_pillars) and self.n_pillars >= 1,
                 "n_pillars", self.n_pillars, "an integer N >= 1")
        if self.layout == "regular":
            side = math.isqrt(self.n_pillars)
            require(side * side == self.n_pillars, "n_pillars", self.n_pillars,
                     "a perfect square (1, 4, 9, 16, ...) for regular brushes")
        if self.layout == "hexagonal" and hexagonal_lattice(self.n_pillars) is None:
            lower, upper = nearest_hexagonal_counts(self.n_pillars)
            require(False, "n_pillars", self.n_pillars,
                     "a count that fills a hexagonal lattice, e.g. "
                     + (f"{lower} or {upper}" if lower else f"{upper}"),
                     f"a hexagonal lattice needs rows x columns = N with rows/columns within "
                     f"a factor {HEX_ASPECT_TOLERANCE:g} of 2/sqrt(3)")
        self._check_shape()
        require(is_real(self.kbar) and not math.isnan(self.kbar) and self.kbar >= MIN_KBAR,
                 "kbar", self.kbar, f"a number in [{MIN_KBAR:g}, inf]; inf means rigid pillars"
                 + (f" (a number, not a string{_as_number(self.kbar)})"
                    if isinstance(self.kbar, str) else ""))
        require(is_integer(self.grid) and MIN_GRID <= self.grid <= MAX_GRID, "grid", self.grid,
                 f"an integer in [{MIN_GRID}, {MAX_GRID}]")
        require(is_real(self.phi) and 0.0 < self.phi <= MAX_PHI, "phi", self.phi,
                 f"a number in (0, {MAX_PHI:g}]")
        require(is_integer(self.seed) and 0 <= self.seed <= MAX_SEED, "seed", self.seed,
                 "an integer in [0, 2**63 - 1]")
        require(is_real(self.min_gap) and 1.0 <= self.min_gap < RANDOM_GAP_GRID,
                 "min_gap", self.min_gap,
                 f"a number of L / {RANDOM_GAP_GRID} lengths in [1, {RANDOM_GAP_GRID})")
        if self.layout != "random" and self.min_gap != 1.0:
            # as the CLI does: kept, it would give one brush two parameter hashes
            # and stop its curves aggregating with the workflow's
            warnings.warn(f"min_gap applies to random layouts only: the {self.layout} layout "
                          f"ignores min_gap {self.min_gap:g}, recorded as 1", stacklevel=4)
            object.__setattr__(self, "min_gap", 1.0)
        low, high = UNIT_RANGE
        for name in ("e_star", "dgamma", "h"):
            value = getattr(self, name)
            require(is_real(value) and low <= value <= high, name, value,
                     f"a number in [{low:g}, {high:g}]")
        require_switches(self, ("allow_coarse",), "True or False")
        self._check_rough()
        require(is_one_of(self.backend, BACKENDS), "backend", self.backend,
                 "'cpu' (the default) or 'gpu' ('strict': the tests' array-API check)")
        r = self.narrowest_radius_elements
        floor = FLOOR_RADIUS_ELEMENTS if self.allow_coarse else MIN_RADIUS_ELEMENTS
        needed = math.ceil(floor * self.grid / r)
        what = ("an ellipse's semi-minor axis" if self.shape == "ellipse"
                else "a pillar radius")
        require(r >= floor, "grid", self.grid,
                 (f"grid >= {needed}"
                  + ("" if self.allow_coarse else " (or allow_coarse to run it anyway)"))
                 if needed <= MAX_GRID else
                 f"none up to {MAX_GRID} resolves these pillars: "
                 + ("a table's x, y and radius are in units of L, the square's side (in "
                    "metres or microns? divide them by L)"
                    # a pillar table (`pillar_table.is_table`, which imports this module)
                    if self.layout_file.lower().endswith(".csv") else
                    "fewer pillars or a larger filling factor"),
                 f"{what} spans {r:.3g} elements, under the {floor:.3g} "
                 + ("that cover an element centre" if self.allow_coarse else
                    "needed for a meaningful detachment criterion"))

    def _check_shape(self) -> None:
        """Validate shape, aspect, orientation and layout_file (after the layout)."""
        if not isinstance(self.layout_file, str) and hasattr(self.layout_file, "__fspath__"):
            object.__setattr__(self, "layout_file", str(self.layout_file))
        require(isinstance(self.layout_file, str), "layout_file", self.layout_file,
                 "a path (str or os.PathLike)")
        if self.layout == "file":
            require(self.layout_file != "", "layout_file", self.layout_file,
                     "the path of a .npy label map, .png image or .csv pillar table "
                     "for the file layout")
        else:
            require(self.layout_file == "", "layout_file", self.layout_file,
                     "no layout file unless layout is 'file'")
        require(is_one_of(self.shape, SHAPES), "shape", self.shape, f"one of {SHAPES}")
        require(self.layout != "file" or self.shape == "disc", "shape", self.shape,
                 "the default 'disc' with layout 'file' (its shapes come from the file)")
        require(is_real(self.aspect) and 1.0 <= self.aspect <= MAX_ASPECT, "aspect",
                 self.aspect, f"a number in [1, {MAX_ASPECT:g}]")
        require(self.shape == "ellipse" or self.aspect == 1.0, "aspect", self.aspect,
                 "1 unless shape is 'ellipse'")
        # beyond a turn an angle says nothing more (1e308 passed, and the grid
        # rule then blamed the grid for its rounding)
        require(is_real(self.orientation) and abs(self.orientation) <= MAX_ORIENTATION,
                 "orientation", self.orientation,
                 f"an angle in degrees in [-{MAX_ORIENTATION:g}, {MAX_ORIENTATION:g}]")
        require(self.shape in ("square", "ellipse") or self.orientation == 0.0,
                 "orientation", self.orientation, "0 unless shape is 'square' or 'ellipse'")

    def _check_rough(self) -> None:
        """Roughness, preload, stiffness spread and the per-pillar arrays."""
        for name, high in (("roughness", MAX_ROUGH), ("preload", MAX_ROUGH),
                           ("kbar_spread", MAX_KBAR_SPREAD)):
            value = getattr(self, name)
            require(is_real(value) and 0 <= value <= high, name, value,
                     f"a number in [0, {high:g}]")
        require(self.kbar_spread == 0 or math.isfinite(self.kbar), "kbar_spread",
                 self.kbar_spread, "0 for rigid pillars (kbar = inf)")
        n = self.n_pillars
        if self.kbar_spread > 0 and self.kbar_values is None:
            # The draws themselves must stay where the solver works, as values
            # from a file must (a spread of 100 at kbar 1e-9 drew 1e-15).
            low = float(lognormal_kbar(self.kbar, self.kbar_spread, n, self.seed).min())
            require(low >= MIN_KBAR, "kbar_spread", self.kbar_spread,
                     f"a spread whose draws stay at or above kbar {MIN_KBAR:g} (a smaller "
                     "spread, a larger kbar or another seed)",
                     f"a draw reaches kbar {low:.3g} at mean {self.kbar:g} with this seed "
                     f"({self.seed})")
        digest = hashlib.sha256()
        for name, shape, low in (("heights", (n,), None), ("kbar_values", (n,), MIN_KBAR),
                                 ("gap_map", (self.grid, self.grid), None)):
            value = getattr(self, name)
            if value is None:
                continue
            what = (f"an array of shape {shape}" if name == "gap_map" else
                    f"one value per pillar ({n}), in label order")
            if np.iscomplexobj(value):  # float() would drop the imaginary part
                raise ParameterError(name, "<complex array>", what + ", real numbers")
            try:
                arr = np.array(value, dtype=float)
            except (TypeError, ValueError):
                raise ParameterError(name, type(value).__name__, what) from None
            require(arr.shape == shape, name, f"<array of shape {arr.shape}>", what)
            ok = np.isfinite(arr) if low is None else (np.isfinite(arr) | (arr == np.inf))
            if low is not None:
                ok &= ~(arr < low)
            else:  # heights, gap map: beyond 1e3 d_K a rigid shift loses W to rounding
                ok &= np.abs(arr) <= MAX_ROUGH
            bad = np.argwhere(~ok)
            if bad.size:
                where = ", ".join(str(int(i)) for i in bad[0])
                kind = "element (y, x)" if name == "gap_map" else "pillar"
                allowed = {"kbar_values": f", each in [{MIN_KBAR:g}, inf]"}
                require(False, name, f"<array with {len(bad)} invalid values>",
                         what + allowed.get(name, f", each in [-{MAX_ROUGH:g}, {MAX_ROUGH:g}]"),
                         f"{kind} {where} is {float(arr[tuple(bad[0])])!r}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
            digest.update(name.encode() + arr.tobytes())
        require(self.heights is None or self.roughness == 0, "roughness", self.roughness,
                 "0 when heights are given (they are exclusive)")
        require(self.kbar_values is None or self.kbar_spread == 0, "kbar_spread",
                 self.kbar_spread, "0 beside kbar_values (the two are exclusive)")
        if self.kbar_values is not None and math.isinf(self.kbar):
            # the name a sweep files the brush under: not rigid for soft pillars
            rigid = np.isinf(self.kbar_values)
            require(bool(rigid.all()), "kbar", self.kbar,
                    "a finite name where any pillar's kbar_values is finite (their mean, "
                    "as the CLI records it; a sweep files the brush under kbar), inf only "
                    "where every pillar is rigid",
                    f"{int(rigid.sum())} of {self.n_pillars} pillars are rigid")
        object.__setattr__(self, "inputs_digest", digest.hexdigest()[:16]
                           if any(getattr(self, k) is not None for k in ARRAY_FIELDS) else "")

    @classmethod
    def from_attrs(cls, attrs: Mapping[str, object]) -> BrushParams:
        """The parameters a curve file's attributes record (`as_attrs`).

        Switches stored as 0/1 (netCDF has no booleans) become bools; the
        run's ``backend`` is left at "cpu" (not part of the problem).

        Raises
        ------
        ParameterError
            For ``inputs_digest`` when the run was given per-pillar or
            per-element arrays, which only the curve's variables hold (use
            `from_curve`), and as the constructor for values out of range.
        """
        require(isinstance(attrs, Mapping), "attrs", type(attrs).__name__,
                "a mapping of a curve file's attributes (ds.attrs)")
        missing = [name for name in REQUIRED_FIELDS if name not in attrs]
        require(not missing, "attrs", f"<{len(attrs)} attributes>",
                f"a curve file's attributes, {', '.join(REQUIRED_FIELDS)} among them",
                f"{', '.join(missing)} missing")
        digest = attrs.get("inputs_digest", "")
        require(digest == "", "inputs_digest", digest,
                "'' (no per-pillar arrays) for from_attrs",
                "the run was given heights, kbar_values or gap_map, which only the curve's "
                "variables hold: BrushParams.from_curve(ds) reads them")
        return cls(**_fields_of(attrs))

    @classmethod
    def from_curve(cls, ds: object) -> BrushParams:
        """The parameters of a curve (a Dataset from `simulate` or `read_curve`),
        arrays included: `from_attrs`, plus ``heights``, ``kbar_values`` and
        ``gap_map`` from ``pillar_height_normalized``, ``pillar_kbar`` and
        ``gap_map_normalized`` [d_K] where the attribute ``inputs_digest``
        says arrays were given; which ones, and that the values are
        bit for bit those given, is checked against that digest.

        Raises
        ------
        ParameterError
            For ``inputs_digest`` when the curve's variables do not reproduce
            it (variables missing, or a file written before they were
            stored as given, 2026-12-05), and as `from_attrs`; for ``ds``
            when it is not a Dataset (a dict of attributes: `from_attrs`).
        """
        require(hasattr(ds, "attrs") and hasattr(ds, "data_vars"), "ds", type(ds).__name__,
                "a curve Dataset (simulate's or read_curve's); for a dict of its attributes, "
                "BrushParams.from_attrs")
        attrs = dict(ds.attrs)
        digest = attrs.pop("inputs_digest", "")
        fields = _fields_of(attrs)
        if digest == "":
            return cls(**fields)
        # Which arrays were given is not recorded apart from the digest: try
        # what the file can hold (a gap map's variable is written only if given).
        found = {name: np.asarray(ds[var].values) for name, var in
                 (("heights", "pillar_height_normalized"), ("kbar_values", "pillar_kbar"),
                  ("gap_map", "gap_map_normalized")) if var in ds}
        optional = [n for n in ("heights", "kbar_values") if n in found]
        for mask in range(2 ** len(optional)):
            chosen = {n: found[n] for k, n in enumerate(optional) if mask >> k & 1}
            if "gap_map" in found:
                chosen["gap_map"] = found["gap_map"]
            try:
                candidate = cls(**fields, **chosen) if chosen else None
            except ParameterError:  # heights beside roughness, say: not this set
                continue
            if candidate is not None and candidate.inputs_digest == digest:
                return candidate
        missing = [var for var in ("pillar_height_normalized", "pillar_kbar") if var not in ds]
        raise ParameterError(
            "inputs_digest", digest, "a digest the curve's own variables reproduce",
            (f"the curve lacks {', '.join(missing)}" if missing else
             "its pillar_height_normalized, pillar_kbar and gap_map_normalized do not "
             "reproduce it (files written before 2026-12-05 store heights and gap maps "
             "rounded)") + "; pass the arrays to BrushParams(**attrs, heights=...) yourself")

    def __reduce__(self) -> tuple[type, tuple]:
        """Pickle as a call of the constructor on the init fields, so that
        unpickling (multiprocessing, joblib) validates again and stores the
        arrays read-only: pickle copies an array writeable, and a default
        dataclass unpickles without ``__post_init__``."""
        return type(self), tuple(getattr(self, f.name) for f in fields(self) if f.init)

    def __repr__(self) -> str:
        """The constructor call, fields at their defaults left out, so that it
        reads short and pastes back (arrays by their size: pass them again)."""
        kbar = "math.inf" if self.kbar == math.inf else repr(self.kbar)  # rigid, as typed
        parts = [repr(self.layout), repr(self.n_pillars), kbar, repr(self.grid)]
        for f in fields(self)[4:]:
            value = getattr(self, f.name)
            if not f.init or value is None:
                continue
            if isinstance(value, np.ndarray):
                parts.append(f"{f.name}=<{value.size} values>")
            elif value != f.default:
                parts.append(f"{f.name}={value!r}")
        return f"BrushParams({', '.join(parts)})"

    @property
    def draws_from_seed(self) -> bool:
        """Whether ``seed`` picks anything: a random layout, drawn heights
        (roughness) or drawn stiffnesses (kbar_spread)."""
        return self.layout == "random" or self.roughness > 0 or self.kbar_spread > 0

    @property
    def is_flat(self) -> bool:
        """The flat problem: equal heights and springs, pulled from full contact."""
        return (self.roughness == 0 and self.preload == 0 and self.kbar_spread == 0
                and all(getattr(self, k) is None for k in ARRAY_FIELDS))

    @property
    def side(self) -> float:
        """Side L = n h of the square holding the pillars [length]."""
        return self.grid * self.h

    @property
    def pillar_radius(self) -> float:
        """Pillar radius a_p = L sqrt(phi / (pi N)) [length] (equal-area radius)."""
        return self.side * math.sqrt(self.phi / (math.pi * self.n_pillars))

    @property
    def given_inputs(self) -> str:
        """The arrays this brush was given (`ARRAY_FIELDS`, space-separated;
        "" for none): a curve's attribute of that name, which `sweep.nc`
        keeps per case, so that a brush of given heights is not read as flat."""
        return " ".join(name for name in ARRAY_FIELDS if getattr(self, name) is not None)

    @property
    def pillar_radius_elements(self) -> float:
        """Pillar radius in elements."""
        return self.pillar_radius / self.h

    @property
    def narrowest_radius_elements(self) -> float:
        """Half-width of a pillar across its narrowest direction, in elements,
        which the radius rule asks to be resolved: the equal-area radius of a
        disc or square (a square's half-side is 0.89 of it), an ellipse's
        semi-minor axis r / sqrt(aspect) (aspect 10 on 129^2 at phi 0.03 left
        one element across it, and its soft brush weaker than its rigid one)."""
        return narrowest_radius(self.pillar_radius_elements, self.shape, self.aspect)

    @property
    def pillar_area(self) -> float:
        """Cross-section of one pillar A_p = phi L^2 / N [length^2]."""
        return self.phi * self.side**2 / self.n_pillars

    @property
    def stiffness(self) -> float:
        """Spring stiffness k = kbar E* L [force / length] (inf when rigid)."""
        return stiffness_from_kbar(self.kbar, self.e_star, self.side)

    def as_attrs(self) -> dict[str, float | int | str]:
        """All fields as netCDF-safe attributes (inf kept as a float).

        The rough-brush fields appear only where they differ from their
        defaults, so a flat brush keeps the flat brush's attributes and parameter
        hash; arrays are represented by ``inputs_digest`` (their values are
        curve variables).
        """
        out = {}
        for k, v in asdict(self).items():
            if k in NOT_ATTRIBUTES:
                continue
            if k in ROUGH_FIELDS and v == ROUGH_DEFAULTS[k]:
                continue
            out[k] = int(v) if isinstance(v, bool) else v
        return out


def _as_number(text: str) -> str:
    """": float('...')" where the string reads as a number, else ""."""
    try:
        float(text)
    except ValueError:
        return ""
    return f": float({text!r})"


#: Per-pillar and per-element inputs (arrays) of `BrushParams`.
ARRAY_FIELDS = ("heights", "kbar_values", "gap_map")
#: Fields `as_attrs` leaves out: the arrays (curve variables, represented by
#: ``inputs_digest``) and where a run ran (``backend``), not what it solved.
NOT_ATTRIBUTES = (*ARRAY_FIELDS, "backend")


#: The fields without a default, which every curve file's attributes hold.
REQUIRED_FIELDS = tuple(f.name for f in fields(BrushParams) if f.init and f.default is MISSING
                       and f.default_factory is MISSING)


def _fields_of(attrs: Mapping[str, object]) -> dict[str, object]:
    """The scalar `BrushParams` fields among a curve file's attributes, 0/1
    switches as bools (netCDF has no booleans; other values are left for
    the constructor to refuse)."""
    out = {}
    for f in fields(BrushParams):
        if not f.init or f.name in NOT_ATTRIBUTES or f.name not in attrs:
            continue
        value = attrs[f.name]
        if isinstance(f.default, bool) and is_integer(value) and value in (0, 1):
            value = bool(value)
        out[f.name] = value
    return out


#: Rough-brush fields and the defaults that give the flat brush.
ROUGH_DEFAULTS = {"roughness": 0.0, "preload": 0.0, "kbar_spread": 0.0, "inputs_digest": ""}
ROUGH_FIELDS = tuple(ROUGH_DEFAULTS)
