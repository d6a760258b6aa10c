"""Solving one problem: the operator and FFTs a run needs, and the pull-off or
protocol engine on it (`run`, `run_protocol_curve`).  `brushcore.model.curve`
turns what they return into the curve file's Dataset."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from brushcore.model import theory
from brushcore.model.labelmap import pillar_element_counts
from brushcore.model.layout import build_labels
from brushcore.model.params import BrushParams
from brushcore.numerics.platform.backend import Backend, resolve_backend
from brushcore.numerics.linear.cg import ConvergenceError
from brushcore.numerics.halfspace.convolution import HAVE_PYFFTW, cached_convolver
from brushcore.numerics.halfspace.device_convolution import cached_device_convolver
from brushcore.numerics.halfspace.fft_choice import faster_library
from brushcore.numerics.halfspace.mirror import (Quadrant, cached_mirror_convolver,
                                                 mirror_quadrant)
from brushcore.numerics.linear.operator import BrushOperator
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.linear.precondition import BlockInverse
from brushcore.numerics.events.protocol import dispatches, run_protocol
from brushcore.numerics.events.waypoints import ProtocolCurve, Waypoint
from brushcore.numerics.events.pulloff import Progress, PullOffCurve, SolverError, pull_off
from brushcore.numerics.platform.threads import fft_threads
from brushcore.validation import brief


def spring_compliance(params: BrushParams, n_pillars: int) -> np.ndarray:
    """h^2 / k per pillar [length / stress]; zero for rigid pillars."""
    k = params.stiffness
    value = 0.0 if np.isinf(k) else params.h**2 / k
    return np.full(n_pillars, value)


def run(params: BrushParams, options: SolverOptions = SolverOptions(),
        progress: Progress | None = None, labels: np.ndarray | None = None,
        ) -> tuple[np.ndarray, PullOffCurve, int]:
    """Solve one pull-off.

    Parameters
    ----------
    params, options : the problem and the numerics
    progress : optional callback, see `pull_off`
    labels : the label map `params` describes (`build_labels`), passed by a
        caller that built it already; tests pass transformed maps (a turned
        layout), whose pillar count must be ``params.n_pillars``, but
        `brushcore.simulate` refuses any other map, since the parameters and
        the curve's ``parameter_hash`` would not describe it

    Returns
    -------
    detachment_step map (n, n; -1 outside pillars), the curve, and the
    number of operator applications.

    Notes
    -----
    The mirror-symmetric quadrant path (``options.symmetry``) is CPU-only:
    with ``params.backend`` other than "cpu" the whole grid is solved.
    """
    backend = resolve_backend(params.backend)
    labels = build_labels(params) if labels is None else labels
    compliance = spring_compliance(params, params.n_pillars)
    fold = options.symmetry and backend.on_host
    quadrant = mirror_quadrant(labels, compliance) if fold else None
    if quadrant is None:
        conv = grid_convolver(params, backend, options)
        grid_labels = labels
        double = whole_grid_double(params, options)
    else:  # a quarter of the unknowns, quarter-size transforms
        conv = cached_mirror_convolver(params.grid, params.h, params.e_star, fft_threads(),
                                       single_transforms(params, options, folded=True))
        grid_labels, compliance = quadrant.labels, compliance[quadrant.images[:, 0]]
        double = partial(cached_mirror_convolver, params.grid, params.h, params.e_star,
                         fft_threads(), False)
        if progress is not None:
            progress = _scaled_progress(progress, 4)
    before = conv.applications
    op = BrushOperator(conv, grid_labels, compliance, params.h, params.e_star,
                       precise=double if is_single(conv) else None)
    sigma_c = theory.critical_stress(params.e_star, params.dgamma, params.h)
    try:
        # Vectors are ~1e4-1e5 long: BLAS threads only contend with the FFTs.
        with threadpool_limits(limits=1, user_api="blas"):
            curve = pull_off(op, sigma_c, params.h, options, progress)
    except (ConvergenceError, SolverError) as exc:
        raise type(exc)(f"{exc}; problem: {brief(params)}; options: {brief(options)}") from None
    detach = np.full(grid_labels.size, -1, dtype=np.int32)
    detach[op.elements] = curve.detach_step
    detach = detach.reshape(grid_labels.shape)
    if quadrant is not None:
        detach, curve = quadrant.unfold_field(detach), unfold_curve(quadrant, curve)
    return detach, curve, conv.applications - before + op.refined_applications


def unfold_curve(quadrant: Quadrant, curve: PullOffCurve) -> PullOffCurve:
    """A quadrant's pull-off as the full brush's: forces and counts x 4,
    pillar forces in full label order.  ``detach_step`` stays in the
    quadrant operator's order (unfold its map with `Quadrant.unfold_field`)."""
    peak = curve.pillar_force_at_peak
    return replace(curve, force=curve.force * 4,
                   attached_elements=curve.attached_elements * 4,
                   attached_pillars=curve.attached_pillars * 4,
                   pillar_force_at_peak=None if peak is None else quadrant.unfold_pillars(peak),
                   symmetry_fold=4)


def whole_grid_double(params: BrushParams, options: SolverOptions) -> Callable[[], Any]:
    """The double-precision twin of a run's whole-grid convolver, on the same
    library: what a solve handed over to double precision applies
    (`BrushOperator.refined`)."""
    return partial(cached_convolver, params.grid, params.h, params.e_star, fft_threads(),
                   False, host_library(params, options))


def is_single(conv: Any) -> bool:
    """Whether a convolver transforms in single precision."""
    return getattr(conv, "real_dtype", "float64") == "float32"


def single_transforms(params: BrushParams, options: SolverOptions, folded: bool) -> bool:
    """Whether the host transforms of this run are single precision.

    Layouts that may hold exact mirror images (all but random ones, and any
    brush solved on a mirror quadrant: ``folded``) need their stresses to
    tie, so they keep double precision under ``precision="auto"``.  The
    scipy fallback is always double, and so is a run whose stresses or
    displacements lie beyond what float32 squares without overflow
    (`float32_safe`).
    """
    symmetric = folded or params.layout != "random"
    return HAVE_PYFFTW and options.single_transforms(symmetric) and float32_safe(params)


#: Magnitudes a float32 solve handles: their squares (CG's dot products)
#: stay far inside float32's 3.4e38.
FLOAT32_RANGE = (1e-15, 1e15)


def float32_safe(params: BrushParams) -> bool:
    """Whether the run's stress scale sigma_c, displacement scale sigma_c h / E*
    and element size h all lie in `FLOAT32_RANGE` (E* = 1e30 Pa with h = 1e-9 m
    overflowed float32 in the preconditioner; the units range allows it)."""
    sigma_c = theory.critical_stress(params.e_star, params.dgamma, params.h)
    low, high = FLOAT32_RANGE
    return all(low < v < high for v in (sigma_c, sigma_c * params.h / params.e_star, params.h))


def host_library(params: BrushParams, options: SolverOptions) -> str:
    """The library of a host run's whole-grid FFTs, "fftw" or "mkl":
    ``options.fft_library``, with "auto" (both installed) resolved to the
    faster for this grid, thread count and precision on this machine
    (`brushcore.numerics.halfspace.fft_choice`).  A solve handed over to double
    precision stays on the same library."""
    library = options.host_fft_library()
    if options.fft_library == "auto" and library == "mkl":
        return faster_library(params.grid, params.h, params.e_star, fft_threads(),
                              single_transforms(params, options, folded=False))
    return library


def fft_library_used(params: BrushParams, options: SolverOptions, backend: Backend,
                     symmetry_fold: int) -> str:
    """What a run's transforms ran on: "mkl", "fftw", "scipy" (FFTW missing)
    or "cupy" (a device)."""
    if not backend.on_host:
        return "cupy"
    if symmetry_fold == 1 and host_library(params, options) == "mkl":
        return "mkl"
    return "fftw" if HAVE_PYFFTW else "scipy"


def grid_convolver(params: BrushParams, backend: Backend, options: SolverOptions) -> Any:
    """The whole-grid convolver for ``backend`` (cached per process); a device
    always transforms in double precision."""
    if backend.on_host:
        return cached_convolver(params.grid, params.h, params.e_star, fft_threads(),
                                single_transforms(params, options, folded=False),
                                host_library(params, options))
    return cached_device_convolver(params.grid, params.h, params.e_star, backend)


def _scaled_progress(progress: Progress, factor: int) -> Progress:
    """A progress callback fed quadrant counts, reporting full-brush counts."""
    return lambda events, attached, total: progress(events, attached * factor,
                                                    total * factor)


def run_protocol_curve(params: BrushParams, protocol: tuple[Waypoint, ...],
                       options: SolverOptions = SolverOptions(),
                       heights: np.ndarray | None = None, gap_map: np.ndarray | None = None,
                       compliance: np.ndarray | None = None,
                       progress: Progress | None = None, labels: np.ndarray | None = None,
                       dispatch: bool = True,
                       ) -> tuple[np.ndarray, BrushOperator, ProtocolCurve, int]:
    """Run a loading protocol on a rough and graded brush.

    Parameters
    ----------
    params, options : the problem and the numerics
    protocol : waypoints (see `brushcore.numerics.events.waypoints`), e.g. `preload_protocol(P)`
    heights : protrusion z_p per pillar in label order [length] (default 0);
        a larger z reaches the substrate first
    gap_map : extra gap per element, shape (n, n) [length] (default 0): the
        element offset is z_i = z_p - gap_i (a spherical tip is r^2 / 2R)
    compliance : h^2 / k_p per pillar [length / stress] (default: every
        pillar on the spring of ``params.kbar``)
    progress, labels : as in `run`
    dispatch : see `protocol.run_protocol`

    Returns
    -------
    label map, the operator (its `elements` and `pillar_of` give the order
    of the per-element outputs), the curve, and the operator applications.
    """
    backend = resolve_backend(params.backend)
    labels = build_labels(params) if labels is None else labels
    n_pillars = int(labels.max()) + 1
    conv = grid_convolver(params, backend, options)
    before = conv.applications
    if compliance is None:
        compliance = spring_compliance(params, n_pillars)
    z = element_offsets(labels, heights, gap_map)
    # A run that goes to the pull-off solver takes its block limit: its
    # cascades are local, where the tiles win from 1,500 elements a pillar.
    max_block = (BlockInverse.MAX_BLOCK if dispatch and dispatches(z, protocol)
                 else BlockInverse.MAX_BLOCK_PROTOCOL)
    # A dispatched run is the flat pull-off, whose float32 solves may go on in double.
    op = BrushOperator(conv, labels, np.asarray(compliance, dtype=float), params.h,
                       params.e_star, max_block=max_block,
                       precise=whole_grid_double(params, options) if is_single(conv) else None)
    sigma_c = theory.critical_stress(params.e_star, params.dgamma, params.h)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            curve = run_protocol(op, z, sigma_c, params.h, options, protocol, progress,
                                 dispatch=dispatch)
    except (ConvergenceError, SolverError) as exc:
        raise type(exc)(f"{exc}; problem: {brief(params)}; options: {brief(options)}") from None
    return labels, op, curve, conv.applications - before + op.refined_applications


def element_offsets(labels: np.ndarray, heights: np.ndarray | None,
                    gap_map: np.ndarray | None) -> np.ndarray:
    """Each pillar element's offset z_i = z_p - gap_i [length] in operator
    order (`BrushOperator.elements`: the label map's pillar elements, row by
    row); the first touch is at d = max z."""
    flat_labels = labels.ravel()
    elements = np.flatnonzero(flat_labels >= 0)
    z = np.zeros(elements.size)
    if heights is not None:
        z += np.asarray(heights, dtype=float)[flat_labels[elements]]
    if gap_map is not None:
        z -= np.asarray(gap_map, dtype=float).ravel()[elements]
    return z


#: Loads (preload, force waypoints, in F_K) and height scatter (roughness,
#: the standard deviation of given heights, in d_K) up to this many units run
#: at the rtol asked for; beyond, rtol shrinks as its square (`load_options`).
LOAD_SPAN = 10.0


def load_options(options: SolverOptions, span: float) -> SolverOptions:
    """``options`` with rtol scaled for a protocol whose loads or offsets reach
    ``span`` units of F_K or d_K.

    CG stops at rtol of the largest stress, which a load X times F_K makes
    about X times a pull-off's, and the loop energy is a small difference
    of integrals X^2 times W_K.  Rigid 4 x 4 on 64^2 at roughness and
    preload 1000, rtol 1e-4: F_ad 0.1441 and a dissipated energy of
    -74 W_K, against 0.12900 and +0.20 at rtol 1e-8.  rtol scaled by
    10 / X (1e-6) left the loop energy up to 29 % off over seeds 0-7; by
    (10 / X)^2 (1e-8, 28-35 % more applications) within 0.54 % of rtol
    1e-10.  Up to `LOAD_SPAN` units nothing changes (measured within 5e-4
    of rtol 1e-8 there).  The scaled rtol stops at `SolverOptions.MIN_RTOL`;
    below `SolverOptions.MIXED_MIN_RTOL` (X of about 100) ``precision:
    auto`` runs double-precision transforms (random 16 at X = 200: 14,897
    applications against 11,370 at the old rtol in single precision).
    """
    if span <= LOAD_SPAN:
        return options
    # The loop energy's error goes as rtol X^2 (forces ~X F_K over
    # displacements ~X d_K), so the square keeps its accuracy at large X.
    return _tightened(options, options.rtol * (LOAD_SPAN / span) ** 2)


#: rtol times the span of the pillars' stiffness (`stiffness_span`) up to
#: which a protocol runs at the rtol asked for; beyond, rtol shrinks as 1 /
#: span (`spring_options`).
STIFFNESS_SPAN_RTOL = 0.03


def stiffness_span(compliance: np.ndarray, labels: np.ndarray, h: float,
                   e_star: float) -> float:
    """Largest over smallest effective stiffness of the pillars in contact:
    each pillar's flat-punch contact stiffness 2 a_p E* (a_p its equal-area
    radius) in series with its spring k_p = h^2 / compliance_p (rigid where
    0).  1 for a brush of equal pillars and springs."""
    area = pillar_element_counts(labels, compliance.size) * h * h
    contact = theory.flat_punch_stiffness(np.sqrt(area / np.pi), e_star)
    held = area > 0
    k_eff = 1.0 / (1.0 / contact[held] + np.asarray(compliance, dtype=float)[held] / (h * h))
    return float(k_eff.max() / k_eff.min()) if k_eff.size else 1.0


def spring_options(options: SolverOptions, span: float) -> SolverOptions:
    """``options`` with rtol scaled for a protocol whose pillars' stiffness
    spans ``span`` (`stiffness_span`).

    CG stops at rtol of the largest stress: where rigid and very soft pillars
    are attached together, the soft ones' unit response is ~1 / span of the
    rigid ones', and a protocol moves d far along it (a soft spring lets go
    only after stretching f_c / k).  Regular 2 x 2, two rigid pillars and
    two at kbar 1e-5, 1e-6 or 1e-8 (span 2e4, 2e5, 2e7), heights, preload
    1 F_K, 32^2: W 6 %, 28 % and 28 % off an independent dense solver at
    rtol 1e-4, and within 1e-7 from rtol x span = 0.2 (rtol 1e-5, 1e-6,
    1e-7); at 1.9 one was right and one 6 % off.  So rtol x span stays
    below STIFFNESS_SPAN_RTOL, 0.03, which leaves graded brushes of the
    workflow (span <= ~100) at the rtol asked for.
    """
    if options.rtol * span <= STIFFNESS_SPAN_RTOL:
        return options
    return _tightened(options, STIFFNESS_SPAN_RTOL / span)


def _tightened(options: SolverOptions, rtol: float) -> SolverOptions:
    """``options`` at the smaller ``rtol``, no lower than `SolverOptions.MIN_RTOL`,
    nor below `SolverOptions.MIXED_MIN_RTOL` where the transforms must stay
    float32 (``precision: mixed``); ``auto`` turns to double there."""
    rtol = max(rtol, SolverOptions.MIN_RTOL)
    if options.precision == "mixed":  # float32 transforms reach no further
        rtol = max(rtol, min(options.rtol, SolverOptions.MIXED_MIN_RTOL))
    return replace(options, rtol=min(rtol, options.rtol))
