"""Numerical options of the solvers, validated at the edge."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from brushcore.numerics.platform import mkl
from brushcore.validation import (is_integer, is_one_of, is_real, normalise, require,
                                  require_switches, suggest_keywords)

#: The words `SolverOptions.cascade`, ``precision`` and ``fft_library`` take
#: (the command line offers the same, in this order).
CASCADES = ("global", "local")
PRECISIONS = ("auto", "mixed", "double")
FFT_LIBRARIES = ("auto", "fftw", "mkl")
#: The curve attribute holding the rtol a protocol run was asked for: its
#: ``rtol`` attribute is the one it ran at, tightened for its loads and
#: stiffness span (`brushcore.model.solve.load_options`), which a rerun
#: given it would tighten again.  Written on protocol curves since 2026-12-07.
REQUESTED_RTOL = "rtol_requested"


def short_float(value: float) -> str:
    """A bound as a user would write it: 1e-6, not Python's 1e-06."""
    return np.format_float_scientific(value, trim="-", exp_digits=1)


@suggest_keywords
@dataclass(frozen=True)
class SolverOptions:
    """Numerical options of the pull-off solver.

    The defaults agree with `exact()` within 2e-4 in F_ad and W over the
    paper's sweep; the README's "Method" section gives each option's
    measured effect, and `docs/SPEED.md` its cost.

    Parameters
    ----------
    rtol : CG stops when its error estimate (the preconditioned residual) is
        below rtol times the largest stress, in [1e-12, 1e-3].  The default
        1e-4 moves F_ad by < 1e-4 and W by < 2e-4 against 1e-8 (tested; W
        of a one-drop curve goes as the square of the event displacement).
    max_iter : CG iterations allowed per solve before failing, >= 1.
    tie_rtol : elements whose stress is within this relative distance of the
        critical stress detach together, so that mirror images stay
        symmetric, in [0, 1e-6] (1e-9 was too tight at kbar = 1e-8, where
        the soft springs' round-off reaches ~1e-10); in protocols, gaps
        within tie_rtol x sigma_c K_ii x K_ii / (K_ii + h^2 / k_p) of
        closing (K_ii an element's self-compliance) attach together, a
        window of d that does not grow as 1 / k.
    lookahead : extra relative window of the next event whose elements
        detach (and, in protocols, whose gaps close) in the same batch, in
        [0, 0.1]; 0 (default) is the exact event-driven result, > 0 trades
        accuracy for fewer solves.
    cascade : "local" (default) or "global" (the paper's algorithm, the
        reference).  Both detach, at fixed d, every element above sigma_c
        and re-solve until none is.  "global" re-solves the whole system
        after every round; "local" updates each pillar exactly through its
        own block inverse (or, for pillars beyond the blocks, a solve of
        the pillar alone, `PillarSolver`) and skips a global solve only
        where a rigorous bound on the other pillars' field
        (`BlockInverse.far_field_uncertainty`) shows that it could not flip
        a decision.  Both give the same contact sets.
    symmetry : solve a brush symmetric about both mid-lines (every regular
        flat brush with equal springs) on one quadrant with quarter-size
        transforms (`brushcore.numerics.halfspace.mirror`); True by default, F_ad and
        W within 1e-8 of the whole grid (exact mode).  Protocol runs (preload, rough or
        graded brushes) always solve the whole grid.
    precision : "auto" (default), "mixed" or "double".  "mixed" runs the
        host's FFTs in single precision and applies the block inverses from
        a float32 copy; CG's vectors, dot products, springs and downdates
        stay double, every decision keeps
        `brushcore.numerics.events.decisions.PRECISION_BAND` more margin, and a solve
        unsettled only by it goes on in double.  Float32 breaks the ties of
        mirror images, so "auto" is "mixed" only for layouts without exact
        symmetries (random ones) at rtol >= 1e-6 in units that float32
        holds (`brushcore.model.solve.float32_safe`), else "double"; "mixed"
        needs rtol >= 1e-6 and runs double too beyond those units.  GPU runs
        are always double.
    early_decisions : let a cascade round's CG stop before the tolerance
        once its iterate decides the round
        (`brushcore.numerics.events.decisions.DECISION_SAFETY`); rounds whose
        stresses enter F_ad or W always run to the tolerance.  True by
        default, off in `exact()`.
    settle_decisions : a solve at the tolerance goes on (to 1e-9 at most)
        while an element lies within its margin of sigma_c or of the next
        event's cut, so that which elements detach follows the model, not
        CG's rounding (`brushcore.numerics.events.decisions.settles`; in
        protocols, the cascades' solves against sigma_c).  True by
        default, off in `exact()`.
    fft_library : "auto" (default), "fftw" or "mkl": whose FFTs the host's
        whole-grid transforms run on.  "mkl" needs the ``mkl`` extra
        (``pip install 'brushcore[mkl]'``).  "auto" times both pairs once
        per machine, grid, thread count and precision and runs the faster,
        remembered beside FFTW's wisdom (`brushcore.numerics.halfspace.fft_choice`);
        without mkl_fft it is "fftw".  The two round differently, so curves
        agree to round-off, not to the bit.  The mirror quadrant's DCTs and
        the tiles' local pillar solves stay on FFTW, a GPU on CuPy.
    """

    rtol: float = 1e-4
    max_iter: int = 5000
    tie_rtol: float = 1e-7
    lookahead: float = 0.0
    cascade: str = "local"
    symmetry: bool = True
    precision: str = "auto"
    early_decisions: bool = True
    settle_decisions: bool = True
    fft_library: str = "auto"

    #: Tightest tolerance: double precision's round-off (~1e-16 a product,
    #: grown by the operator's condition) leaves CG nothing to converge to
    #: below it (rtol 1e-300 broke CG down: p.Ap = 0).
    MIN_RTOL = 1e-12
    #: Loosest tolerance accepted (the default is 1e-4).
    MAX_RTOL = 1e-3
    #: Widest tie window: past it ties would join elements that are not
    #: mirror images but merely close (the default is 1e-7).
    MAX_TIE_RTOL = 1e-6
    #: Below this rtol single-precision transforms would limit the accuracy.
    MIXED_MIN_RTOL = 1e-6

    @classmethod
    def exact(cls) -> "SolverOptions":
        """Reference settings: global cascades, CG to 1e-8, double precision."""
        return cls(rtol=1e-8, cascade="global", precision="double", early_decisions=False,
                   settle_decisions=False)

    @classmethod
    def from_attrs(cls, attrs: Mapping[str, object]) -> SolverOptions:
        """The options a curve file's attributes record, as the run was given them.

        Every field is an attribute of the same name (switches stored as
        0/1, netCDF having no booleans), but for a protocol run's ``rtol``:
        the attribute ``rtol`` is the tolerance it ran at, tightened for its
        loads and stiffness span (`brushcore.model.solve.load_options`,
        ``spring_options``), and ``simulate`` would tighten it again; the
        one asked for is `REQUESTED_RTOL` (``rtol_requested``), taken where
        present.  So ``simulate(BrushParams.from_curve(ds),
        SolverOptions.from_curve(ds), protocol=...)`` repeats the run: the
        same tightening, the same ``parameter_hash``, and the same numbers
        where the FFT library and thread count are the curve's
        (``fft_library_used``, ``threads``: "auto" may time the libraries
        otherwise on another machine, and threaded FFTW plans round otherwise).

        Warns
        -----
        UserWarning
            For a protocol curve written before ``rtol_requested`` was
            (2026-12-07): its ``rtol`` is taken, which a rerun tightens again
            where the first run was tightened (a more accurate rerun, not the
            same numbers).

        Raises
        ------
        ParameterError
            For ``attrs`` when it is not a mapping or lacks an option (files
            written before 2026-12-03 lack ``fft_library``), and as the
            constructor for values out of range.
        """
        return cls._from_recorded(attrs)

    @classmethod
    def from_curve(cls, ds: object) -> SolverOptions:
        """The options of a curve (a Dataset from `simulate` or `read_curve`),
        as the run was given them: `from_attrs` of its attributes.

        Raises
        ------
        ParameterError
            For ``ds`` when it is not a Dataset (a dict of attributes:
            `from_attrs`), and as `from_attrs`.
        """
        require(hasattr(ds, "attrs") and hasattr(ds, "data_vars"), "ds", type(ds).__name__,
                "a curve Dataset (simulate's or read_curve's); for a dict of its attributes, "
                "SolverOptions.from_attrs")
        return cls._from_recorded(ds.attrs)

    @classmethod
    def _from_recorded(cls, attrs: Mapping[str, object]) -> SolverOptions:
        """`from_attrs`' work: the fields of ``attrs``, a protocol's rtol from
        `REQUESTED_RTOL`, warned of at its caller's caller (the user's line)
        where the file predates it."""
        require(isinstance(attrs, Mapping), "attrs", type(attrs).__name__,
                "a mapping of a curve file's attributes (ds.attrs)")
        names = [f.name for f in fields(cls)]
        missing = [name for name in names if name not in attrs]
        require(not missing, "attrs", f"<{len(attrs)} attributes>",
                f"a curve file's attributes, the solver options {', '.join(names)} among them",
                f"{', '.join(missing)} missing")
        values = {}
        for f in fields(cls):
            value = attrs[f.name]
            if isinstance(f.default, bool) and is_integer(value) and value in (0, 1):
                value = bool(value)  # netCDF's 0/1; other values left for the check
            values[f.name] = value
        if REQUESTED_RTOL in attrs:
            values["rtol"] = attrs[REQUESTED_RTOL]
        elif "protocol" in attrs:  # every protocol curve's; a flat run never tightens
            warnings.warn(
                f"the curve records the rtol its protocol ran at ({values['rtol']!r}), "
                f"not the one asked for ({REQUESTED_RTOL}, written since 2026-12-07): a "
                "rerun tightens it again where the run was tightened for its loads or "
                "stiffness span, more accurate than the curve, not the same numbers",
                stacklevel=3)
        return cls(**values)

    def __post_init__(self) -> None:
        normalise(self, ("max_iter",), ("rtol", "tie_rtol", "lookahead"),
                  ("cascade", "precision", "fft_library"))
        require(is_real(self.rtol) and self.MIN_RTOL <= self.rtol <= self.MAX_RTOL, "rtol",
                self.rtol, f"a number in [{self.MIN_RTOL:g}, "
                f"{short_float(self.MAX_RTOL)}]")
        require(is_integer(self.max_iter) and self.max_iter >= 1, "max_iter",
                 self.max_iter, "an integer >= 1")
        require(is_real(self.tie_rtol) and 0 <= self.tie_rtol <= self.MAX_TIE_RTOL, "tie_rtol",
                self.tie_rtol, f"a number in [0, {short_float(self.MAX_TIE_RTOL)}]")
        require(is_real(self.lookahead) and 0 <= self.lookahead <= 0.1, "lookahead",
                 self.lookahead, "a number in [0, 0.1]")
        require(is_one_of(self.cascade, CASCADES), "cascade", self.cascade,
                 "'local' or 'global'")
        require_switches(self, ("symmetry", "early_decisions", "settle_decisions"),
                         "true or false")
        require(is_one_of(self.precision, PRECISIONS), "precision", self.precision,
                "'auto', 'mixed' or 'double'")
        require(is_one_of(self.fft_library, FFT_LIBRARIES), "fft_library", self.fft_library,
                "'auto', 'fftw' or 'mkl'")
        require(self.fft_library != "mkl" or mkl.available(), "fft_library", self.fft_library,
                "'auto' or 'fftw' here: 'mkl' needs mkl_fft (pip install 'brushcore[mkl]')")
        require(self.precision != "mixed" or self.rtol >= self.MIXED_MIN_RTOL, "rtol",
                self.rtol, f"a number >= {self.MIXED_MIN_RTOL:g} with precision 'mixed' "
                "(use precision 'double' for tighter tolerances)")

    def single_transforms(self, symmetric: bool) -> bool:
        """Whether host FFTs run in single precision (see ``precision``) for a
        layout that may (``symmetric``) or cannot hold exact mirror images."""
        return self.precision == "mixed" or (self.precision == "auto" and not symmetric
                                             and self.rtol >= self.MIXED_MIN_RTOL)

    def host_fft_library(self) -> str:
        """The library ``fft_library`` names: "mkl" or "fftw", "auto" read as
        "mkl" where it is installed.  Which one a run's transforms use is
        `brushcore.model.solve.host_library`'s choice, which times "auto"'s
        two on the machine and may take FFTW."""
        if self.fft_library == "auto":
            return "mkl" if mkl.available() else "fftw"
        return self.fft_library
