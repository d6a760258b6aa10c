"""One pull-off from parameters to an xarray Dataset (the curve file content)."""

from __future__ import annotations

import datetime as dt
import hashlib
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from . import theory
from .convolution import cached_convolver
from .lattices import hexagonal_fill, hexagonal_lattice
from .layout import build_labels
from .operator import BrushOperator
from .params import BrushParams, SolverOptions
from .provenance import git_commit, parameter_hash, version
from .cg import ConvergenceError
from .pulloff import Progress, PullOffCurve, SolverError, pull_off
from .threads import fft_threads

#: How to read dimensional values: the inputs define the unit system.
UNITS_CONVENTION = ("SI: e_star in Pa, dgamma in J m-2, h in m, so lengths in m, forces in N, "
                    "energies in J; with the defaults e_star = dgamma = h = 1 the values are "
                    "in units of h, E* h^2 and dgamma h^2")
#: Definitions of the symbols used in long names.
SYMBOLS = ("A: real contact area (pillar elements x h^2); a0 = sqrt(A / pi): radius of one "
           "compact punch of area A; F_K = sqrt(8 pi E* dgamma a0^3): Kendall's pull-off "
           "force of that punch; d_K = sqrt(2 pi dgamma a0 / E*); W_K = 2 pi a0^2 dgamma; "
           "kbar = k / (E* L), L = grid h; phi = A / L^2")

SNAPSHOT_LABELS = ("start", "before maximum", "maximum force", "after maximum",
                   "last contact")


def spring_compliance(params: BrushParams, n_pillars: int) -> np.ndarray:
    """h^2 / k per pillar [length / stress]; zero for rigid pillars."""
    k = params.stiffness
    value = 0.0 if np.isinf(k) else params.h**2 / k
    return np.full(n_pillars, value)


def snapshot_steps(area: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Steps for the contact snapshots of Fig. 5 (see SNAPSHOT_LABELS).

    Between the start and the maximum, and between the maximum and the last
    contact, the stage whose contact area is halfway is chosen.
    """
    i_max = int(np.argmax(force))
    i_last = int(np.flatnonzero(area > 0)[-1])

    def halfway(a: int, b: int) -> int:
        target = 0.5 * (area[a] + area[b])
        return a + int(np.argmin(np.abs(area[a:b + 1] - target)))

    return np.array([0, halfway(0, i_max), i_max, halfway(i_max, i_last), i_last],
                    dtype=np.int32)


def geometry_attrs(params: BrushParams, labels: np.ndarray) -> dict[str, float | int | str]:
    """What the layout realised: pillar count, hexagonal rows x columns and fill, file digest.

    ``shape``, ``aspect``, ``orientation`` and ``layout_file`` themselves are
    parameters (see `BrushParams.as_attrs`); ``pillar_radius`` is the
    equal-area radius for every shape.
    """
    attrs: dict[str, float | int | str] = {"n_pillars_realised": int(labels.max()) + 1}
    if params.layout == "hexagonal":
        attrs["lattice_rows"], attrs["lattice_columns"] = hexagonal_lattice(params.n_pillars)
        attrs["lattice_fill"] = hexagonal_fill(params.n_pillars)
    if params.layout == "file":
        attrs["layout_file_sha256"] = hashlib.sha256(
            Path(params.layout_file).read_bytes()).hexdigest()
    return attrs


def run(params: BrushParams, options: SolverOptions = SolverOptions(),
        progress: Progress | None = None, labels: np.ndarray | None = None,
        ) -> tuple[np.ndarray, PullOffCurve, int]:
    """Solve one pull-off.

    Parameters
    ----------
    params, options : the problem and the numerics
    progress : optional callback, see `pull_off`
    labels : a label map to use instead of the one `params` describes
        (for transformed or hand-made layouts); its pillar count must be
        ``params.n_pillars``

    Returns
    -------
    detachment_step map (n, n; -1 outside pillars), the curve, and the
    number of operator applications.
    """
    labels = build_labels(params) if labels is None else labels
    conv = cached_convolver(params.grid, params.h, params.e_star, fft_threads())
    before = conv.applications
    op = BrushOperator(conv, labels, spring_compliance(params, params.n_pillars),
                       params.h, params.e_star)
    sigma_c = theory.critical_stress(params.e_star, params.dgamma, params.h)
    try:
        # Vectors are ~1e4-1e5 long: BLAS threads only contend with the FFTs.
        with threadpool_limits(limits=1, user_api="blas"):
            curve = pull_off(op, sigma_c, params.h, options, progress)
    except (ConvergenceError, SolverError) as exc:
        raise type(exc)(f"{exc}; problem: {params}; options: {options}") from None
    detach = np.full(labels.size, -1, dtype=np.int32)
    detach[op.elements] = curve.detach_step
    return detach.reshape(labels.shape), curve, conv.applications - before


def simulate(params: BrushParams, options: SolverOptions = SolverOptions(),
             progress: Progress | None = None, labels: np.ndarray | None = None,
             ) -> xr.Dataset:
    """Pull-off curve, adhesive force and work of separation as a Dataset.

    ``labels`` (optional) is the label map to use, see `run`.

    Signs: d > 0 pulls the brush away, F > 0 is tensile.  Normalised values
    follow the paper (eqs. 20-24) with A the discretised real contact area.
    """
    t0 = time.perf_counter()
    labels = build_labels(params) if labels is None else labels
    detach, curve, applications = run(params, options, progress, labels)
    wall = time.perf_counter() - t0
    h, es, dg = params.h, params.e_star, params.dgamma
    area_total = float(np.count_nonzero(detach >= 0)) * h * h
    fs = theory.force_scale(area_total, es, dg)
    ds_ = theory.displacement_scale(area_total, es, dg)
    ws = theory.work_scale(area_total, dg)
    area = curve.attached_elements * h * h
    i_max = int(np.argmax(curve.force))
    f_ad = float(curve.force[i_max])
    work = float(np.trapezoid(curve.force, curve.displacement))  # exact: piecewise linear
    snaps = snapshot_steps(area, curve.force)
    pillar = detach >= 0
    states = np.where(pillar[None], (detach[None] > snaps[:, None, None]).astype(np.int8),
                      np.int8(-1)).astype(np.int8)
    coord = (np.arange(params.grid) + 0.5) * h

    def var(dims, data, name, units, **extra):
        return xr.Variable(dims, data, {"long_name": name, "units": units, **extra})

    data = {
        "displacement": var("step", curve.displacement, "pull-off displacement d", "m"),
        "force": var("step", curve.force, "tensile normal force F", "N"),
        "contact_area": var("step", area, "real contact area", "m2"),
        "attached_pillars": var("step", curve.attached_pillars.astype(np.int32),
                                "pillars with attached elements", "1"),
        "displacement_normalized": var("step", curve.displacement / ds_,
                                       "d / d_K, d_K = sqrt(2 pi dgamma a0 / E*)", "1"),
        "force_normalized": var("step", curve.force / fs,
                                "F / F_K, F_K = sqrt(8 pi E* dgamma a0^3)", "1"),
        "detachment_step": var(("y", "x"), detach, "first step at which the element is "
                               "detached", "1", comment="-1 outside pillars"),
        "contact_snapshot": var(("snapshot", "y", "x"), states, "contact state", "1",
                                flag_values=np.array([-1, 0, 1], dtype=np.int8),
                                flag_meanings="no_pillar detached attached"),
        "snapshot_step": var("snapshot", snaps, "step of the snapshot", "1"),
        "snapshot_label": xr.Variable("snapshot", np.array(SNAPSHOT_LABELS),
                                      {"long_name": "stage of the pull-off"}),
        "adhesive_force": var((), f_ad, "adhesive force (maximum tensile force)", "N"),
        "adhesive_force_normalized": var((), f_ad / fs, "F_ad / F_K", "1"),
        "displacement_at_adhesive_force": var((), float(curve.displacement[i_max]),
                                              "d at the adhesive force", "m"),
        "work_of_separation": var((), work, "work of separation, integral of F dd", "J"),
        "work_of_separation_normalized": var((), work / ws, "W / W_K, W_K = 2 pi a0^2 dgamma",
                                             "1"),
    }
    attrs = {
        **params.as_attrs(),
        **{k: v for k, v in asdict(options).items()},
        "phi_actual": area_total / params.side**2,
        "real_contact_area": area_total,
        "pillar_radius": params.pillar_radius,
        "pillar_radius_elements": params.pillar_radius_elements,
        "side_length": params.side,
        "critical_stress": theory.critical_stress(es, dg, h),
        "events": curve.events,
        "steps": int(curve.displacement.size),
        "operator_applications": applications,
        "cg_iterations": curve.cg_iterations,
        "wall_time_s": wall,
        "brushcore_version": version(),
        "git_commit": git_commit(),
        "parameter_hash": parameter_hash(params.as_attrs(), asdict(options)),
        "Conventions": "CF-1.10",
        "title": "Adhesive pull-off of a spring-mounted pillar brush",
        "references": "He, Li & Popov, Lubricants 8 (2020) 94; Pohrt & Popov, "
                      "Facta Univ. Mech. Eng. 13 (2015) 3",
        "history": f"{dt.datetime.now(dt.timezone.utc).isoformat(timespec='seconds')} "
                   f"brushcore {version()} simulate",
        "sign_convention": "d > 0 pulls away from the half space; F > 0 is tensile",
        **geometry_attrs(params, labels),
        "units_convention": UNITS_CONVENTION,
        "symbols": SYMBOLS,
    }
    return xr.Dataset(data, coords={
        "step": var("step", np.arange(curve.displacement.size, dtype=np.int32),
                    "step of the pull-off (one per solve)", "1"),
        "y": var("y", coord, "element centre y", "m"),
        "x": var("x", coord, "element centre x", "m"),
        "snapshot": var("snapshot", np.arange(snaps.size, dtype=np.int32),
                        "contact snapshot index", "1"),
    }, attrs=attrs)
