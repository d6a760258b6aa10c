"""Numerical options of the solvers, validated at the edge."""

from __future__ import annotations

from dataclasses import dataclass

from brushcore.numerics import mkl
from brushcore.validation import is_integer, is_real, normalise, require, require_switches


@dataclass(frozen=True)
class SolverOptions:
    """Numerical options of the pull-off solver.

    Parameters
    ----------
    rtol : CG stops when its error estimate (the preconditioned residual) is
        below rtol times the largest stress, in [1e-12, 1e-3], and, with
        ``settle_decisions``, no decision it leads to could flip.  The
        default 1e-4 moves F_ad and W by < 1e-4 against 1e-8 (measured and
        tested); use `SolverOptions.exact()` for reference results.
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
        block inverse (or, for pillars beyond the blocks, a solve of the
        pillar alone on a small FFT grid, `PillarSolver`), holding the other
        pillars' field, and continues without a global solve only while a
        bound on that field's change (first order, rigorous, x3; see
        `BlockInverse.far_field_uncertainty`; on the tile path with a
        measured bound on the inverse's row sums, `PillarSolver.REACH`)
        cannot flip any decision; it always re-solves globally before the
        next event.  Measured against "global": the same contact sets (F_ad
        and W equal to round-off) from kbar 1e-6 to rigid, with 0-3 % fewer
        operator applications.  (Before this bound a monopole estimate saved
        2-4x on soft brushes by deciding wrongly: W up to 0.7 % off.)
    symmetry : solve a brush that is symmetric about both mid-lines (every
        regular flat brush with equal springs) on one quadrant, with
        quarter-size transforms (`brushcore.numerics.mirror`); True by
        default.  The physics is the same: the full solver detaches mirror
        images together (tie_rtol); measured F_ad and W agree within 1e-9.
        False solves the whole grid (a check, or a reference).  Protocol
        runs (preload, rough or graded brushes) always solve the whole grid.
    precision : "auto" (default), "mixed" or "double".  "mixed" runs the
        host's FFTs in single precision (1.4-1.8x faster) and applies the
        block inverses from a float32 copy; CG's vectors and dot products,
        springs and the inverses' downdates stay in double.  The transforms'
        relative error, ~1e-7, lies three orders below the default CG
        tolerance, but it is not symmetric: mirror
        images no longer tie (tie_rtol), and soft symmetric brushes, whose
        cascades depend on the order of near-equal pillars, then take
        another path (regular 576 at kbar 1e-6: W 0.8 % off).  "auto" is
        therefore "mixed" only for layouts without exact symmetries (random
        ones) at rtol >= 1e-6, and "double" otherwise; "mixed" needs rtol
        >= 1e-6.  GPU runs are always double.  What CG's error estimate
        cannot see (it converges on the float32 operator): the round-off
        moves a solution by up to 1.45e-5 of its largest stress (measured
        on random brushes at 512^2), enough to reorder soft random pillars
        that reach sigma_c closer together than that, so while the
        transforms are float32 every decision margin holds
        `brushcore.numerics.pulloff.PRECISION_BAND` (1.5e-5 of the largest
        stress) more, and a solve unsettled only by it goes on in double:
        random 1620 at kbar 1e-5 ended 3.4e-4 off `exact()` in W under
        "mixed" with some sets of FFTW plans before, 6e-8 with the band;
        the sweep's random curves lie within 8.1e-6 of "double" in W on
        one set of plans and within 9.5e-5 on another, at 10.8 % more job
        time ("double": 45 %).
    early_decisions : let a cascade round's CG stop before the tolerance
        once its iterate decides the round (see
        `brushcore.numerics.pulloff.DECISION_SAFETY`); rounds whose stresses
        enter F_ad or W always run to the tolerance.  True by default, off
        in `exact()`.
    settle_decisions : a solve at the tolerance goes on (to 1e-9 at most)
        while an element lies within its margin of sigma_c or of the next
        event's cut (three times its own error estimate plus 0.3 times the
        largest), so that which elements detach follows the
        model, not CG's rounding (`brushcore.numerics.pulloff._settles`);
        float32 transforms hand such a solve over to double.  Without it a
        soft random brush's W followed the warm start: random 1620 at kbar
        3e-6, 512^2, 4.6e-4 off `exact()` after a better warm start, 2e-8
        with it.  True by default, off in `exact()`.
    fft_library : "auto" (default), "fftw" or "mkl": whose FFTs the host's
        whole-grid transforms run on.  "mkl" needs the ``mkl`` extra
        (``pip install 'brushcore[mkl]'``, Intel's MKL through mkl_fft;
        `brushcore.numerics.mkl`): on an Intel Xeon 0.68x FFTW's time a
        pruned pair in single precision and 0.86x in double, a soft random
        curve 25-27 % faster on one thread; with two threads (BRUSHCORE_THREADS,
        the workflow's ``threads``) 0.57-0.75x FFTW's threaded plans, and
        the same numbers to the bit as on one.  On an AMD EPYC FFTW is the
        faster below 2048^2.  "auto" (with both installed) times the two
        pairs once per machine, grid, thread count and precision and runs
        the faster, remembered beside FFTW's wisdom
        (`brushcore.numerics.fft_choice`); without mkl_fft it is "fftw".
        The two round differently,
        so curves agree to round-off and not to the bit (over the default
        sweep F_ad within 3.8e-6, W within 5.0e-5 but on one soft random
        curve, whose near-ties gave it two W 3.4e-4 apart between two sets
        of FFTW plans as well before the float32 band, see ``precision``).  The
        mirror quadrant's DCTs (regular brushes) stay on FFTW, a GPU on
        CuPy, and the tiles' local pillar solves run on planned FFTW
        whatever the choice (3.4x faster than MKL there,
        `brushcore.numerics.pillar_solve.BoxTransforms`).
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
    #: Below this rtol single-precision transforms would limit the accuracy.
    MIXED_MIN_RTOL = 1e-6

    @classmethod
    def exact(cls) -> "SolverOptions":
        """Reference settings: global cascades, CG to 1e-8, double precision."""
        return cls(rtol=1e-8, cascade="global", precision="double", early_decisions=False,
                   settle_decisions=False)

    def __post_init__(self) -> None:
        normalise(self, ("max_iter",), ("rtol", "tie_rtol", "lookahead"))
        require(is_real(self.rtol) and self.MIN_RTOL <= self.rtol <= 1e-3, "rtol", self.rtol,
                 f"a number in [{self.MIN_RTOL:g}, 1e-3]")
        require(is_integer(self.max_iter) and self.max_iter >= 1, "max_iter",
                 self.max_iter, "an integer >= 1")
        require(is_real(self.tie_rtol) and 0 <= self.tie_rtol <= 1e-6, "tie_rtol",
                 self.tie_rtol, "a number in [0, 1e-6]")
        require(is_real(self.lookahead) and 0 <= self.lookahead <= 0.1, "lookahead",
                 self.lookahead, "a number in [0, 0.1]")
        require(self.cascade in ("local", "global"), "cascade", self.cascade,
                 "'local' or 'global'")
        require_switches(self, ("symmetry", "early_decisions", "settle_decisions"),
                         "true or false")
        require(self.precision in ("auto", "mixed", "double"), "precision", self.precision,
                "'auto', 'mixed' or 'double'")
        require(self.fft_library in ("auto", "fftw", "mkl"), "fft_library", self.fft_library,
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
        """The library the host's whole-grid FFTs run on: "mkl" or "fftw"
        (see ``fft_library``)."""
        if self.fft_library == "auto":
            return "mkl" if mkl.available() else "fftw"
        return self.fft_library
