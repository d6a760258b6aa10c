"""One pull-off from parameters to an xarray Dataset (the curve file content):
`simulate` runs `brushcore.model.solve` and describes what it returns."""

from __future__ import annotations

import datetime as dt
import hashlib
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import xarray as xr

from brushcore.model import theory
from brushcore.model.inputs import PROTOCOL_LOADS, load_beyond_range, protocol_text
from brushcore.model.labelmap import count_touching_pairs, pillar_element_counts
from brushcore.model.lattices import hexagonal_fill, hexagonal_lattice
from brushcore.model.layout import build_labels, random_gap, smallest_radius_elements
from brushcore.model.params import MAX_ROUGH, BrushParams
from brushcore.model.provenance import (code_digest, git_commit, parameter_hash,
                                        software_versions, source, version)
from brushcore.model.rough import pillar_centroids, pillar_inputs
from brushcore.model.scales import unit_scales
from brushcore.model.solve import (LOAD_SPAN, element_offsets, fft_library_used, load_options,
                                   run, run_protocol_curve, single_transforms, spring_options,
                                   stiffness_span)
from brushcore.numerics.platform.backend import resolve_backend
from brushcore.numerics.platform.threads import fft_threads
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.events.waypoints import (APPROACH, RETRACT, START, Waypoint,
                                                 loop_energy, positive_work, preload_protocol)
from brushcore.numerics.events.pulloff import Progress
from brushcore.validation import ParameterError

#: How to read dimensional values: the inputs define the unit system.
UNITS_CONVENTION = ("SI: e_star in Pa, dgamma in J m-2, h in m, so lengths in m, forces in N, "
                    "energies in J; with the defaults e_star = dgamma = h = 1 the values are "
                    "in units of h, E* h^2 and dgamma h^2")
#: SI units that mean element units where e_star = dgamma = h = 1 (`mark_element_units`).
DIMENSIONAL_UNITS = ("m", "m2", "N", "J")
ELEMENT_UNITS_COMMENT = ("run with e_star = dgamma = h = 1 (the defaults, and the workflow's): "
                         "the value is in units of h, E* h^2 or dgamma h^2, not of a material; "
                         "the *_normalized variables are the results")


def mark_element_units(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with a comment on every dimensional variable where it ran with
    e_star = dgamma = h = 1: a reader of its units (N, m, J) would otherwise
    take element units for a material's."""
    if all(float(ds.attrs.get(key, math.nan)) == 1.0 for key in ("e_star", "dgamma", "h")):
        for variable in ds.variables.values():
            comment = variable.attrs.get("comment", "")
            if variable.attrs.get("units") in DIMENSIONAL_UNITS and \
                    ELEMENT_UNITS_COMMENT not in comment:  # a sweep of marked curves
                variable.attrs["comment"] = "; ".join(filter(None, (comment,
                                                                    ELEMENT_UNITS_COMMENT)))
    return ds


#: Definitions of the symbols used in long names.
SYMBOLS = ("A: real contact area (pillar elements x h^2); a0 = sqrt(A / pi): radius of one "
           "compact punch of area A; F_K = sqrt(8 pi E* dgamma a0^3): Kendall's pull-off "
           "force of that punch; d_K = sqrt(2 pi dgamma a0 / E*); W_K = 2 pi a0^2 dgamma; "
           "kbar = k / (E* L), L = grid h; phi = A / L^2")

SNAPSHOT_LABELS = ("start", "before maximum", "maximum force", "after maximum",
                   "last contact")

#: Integer variables whose value means "none" (CF _FillValue, so that xarray
#: reads it as NaN and a mean of steps skips it): a step map outside the
#: pillars or where the element never (de)tached, the waypoint before the
#: first one, and a snapshot of a stage the run never reached (a protocol
#: that never pulls has no maximum force), whose map is all fill; the
#: contact maps' -1 is a flag (no pillar), so their fill is -2.
FILL_VALUES = {"detachment_step": -1, "attachment_step": -1, "branch": -1,
               "snapshot_step": -1, "contact_snapshot": -2}


#: The dtype `simulate` gives each `FILL_VALUES` variable.
FILL_DTYPES = {"detachment_step": np.int32, "attachment_step": np.int32, "branch": np.int32,
               "snapshot_step": np.int32, "contact_snapshot": np.int8}


def fill_value(name: str, dtype) -> np.generic:
    """The `FILL_VALUES` entry of ``name`` as a scalar of ``dtype`` (what
    netCDF's _FillValue of an integer variable must be)."""
    return np.asarray(FILL_VALUES[name], dtype=dtype)[()]


def snapshot_steps(area: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Steps for the contact snapshots of Fig. 5 (see SNAPSHOT_LABELS).

    Between the start and the maximum, and between the maximum and the last
    contact, the stage whose contact ``area`` is halfway is chosen (the first
    of a tie: give element counts, which a unit system cannot round).
    """
    i_max = int(np.argmax(force))
    i_last = int(np.flatnonzero(area > 0)[-1])

    def halfway(a: int, b: int) -> int:
        target = 0.5 * (area[a] + area[b])
        return a + int(np.argmin(np.abs(area[a:b + 1] - target)))

    return np.array([0, halfway(0, i_max), i_max, halfway(i_max, i_last), i_last],
                    dtype=np.int32)


def geometry_attrs(params: BrushParams, labels: np.ndarray) -> dict[str, float | int | str]:
    """What the layout realised: pillar count, pillar pairs whose footprints
    share an element edge (`labelmap.count_touching_pairs`: 0 but for random
    discs on grids coarser than 512, where the gap is under an element),
    hexagonal rows x columns and fill, a random layout's gap [length]
    (`layout.random_gap`), file digest.

    ``shape``, ``aspect``, ``orientation`` and ``layout_file`` themselves are
    parameters (see `BrushParams.as_attrs`); ``pillar_radius`` is the
    equal-area radius for every shape, ``smallest_radius_elements`` the
    narrowest pillar's (`brushcore.model.layout.smallest_radius_elements`).
    """
    attrs: dict[str, float | int | str] = {"n_pillars_realised": int(labels.max()) + 1,
                                           "touching_pillar_pairs": count_touching_pairs(labels),
                                           "smallest_radius_elements":
                                               smallest_radius_elements(params, labels)}
    if params.layout == "random":  # the rule that drew it: gap L min_gap / 512 on every grid
        attrs["random_gap"] = random_gap(params)
    if params.layout == "hexagonal":
        attrs["lattice_rows"], attrs["lattice_columns"] = hexagonal_lattice(params.n_pillars)
        attrs["lattice_fill"] = hexagonal_fill(params.n_pillars)
    if params.layout == "file":
        attrs["layout_file_sha256"] = hashlib.sha256(
            Path(params.layout_file).read_bytes()).hexdigest()
    return attrs


#: What ``dissipated_energy`` is where a protocol does not end in separation.
DISSIPATED_COMMENT = ("the energy dissipated where the protocol runs from first touch to "
                      "separation; a protocol that ends in contact adds the elastic energy "
                      "stored at its end")


def _var(dims, data, name: str, units: str, **extra) -> xr.Variable:
    """A CF variable: values with long_name, units and any extra attributes."""
    return xr.Variable(dims, data, {"long_name": name, "units": units, **extra})


def _filled(name: str, dims, data: np.ndarray, long_name: str, **extra) -> xr.Variable:
    """A dimensionless integer variable ``name`` whose `FILL_VALUES` entry
    means "none": declared as its netCDF _FillValue (`brushcore.data.io`
    writes it), kept as a number in memory."""
    var = _var(dims, data, long_name, "1", **extra)
    var.encoding["_FillValue"] = fill_value(name, var.dtype)
    return var


def _step_variables(displacement: np.ndarray, force: np.ndarray, area: np.ndarray,
                    attached_pillars: np.ndarray, d_unit: float, f_unit: float,
                    displacement_name: str) -> dict[str, xr.Variable]:
    """The curve itself, per step, in SI and normalised (every curve file's)."""
    return {
        "displacement": _var("step", displacement, displacement_name, "m"),
        "force": _var("step", force, "tensile normal force F", "N"),
        "contact_area": _var("step", area, "real contact area", "m2"),
        "attached_pillars": _var("step", attached_pillars.astype(np.int32),
                                "pillars with attached elements", "1"),
        "displacement_normalized": _var("step", displacement / d_unit,
                                       "d / d_K, d_K = sqrt(2 pi dgamma a0 / E*)", "1"),
        "force_normalized": _var("step", force / f_unit,
                                "F / F_K, F_K = sqrt(8 pi E* dgamma a0^3)", "1"),
    }


def _result_variables(f_ad: float, d_ad: float, work: float, f_unit: float, w_unit: float,
                      force_name: str, work_name: str) -> dict[str, xr.Variable]:
    """F_ad, the d it is reached at and W, in SI and normalised (every curve file's)."""
    return {
        "adhesive_force": _var((), f_ad, force_name, "N"),
        "adhesive_force_normalized": _var((), f_ad / f_unit, "F_ad / F_K", "1"),
        "displacement_at_adhesive_force": _var((), d_ad, "d at the adhesive force", "m"),
        "work_of_separation": _var((), work, work_name, "J"),
        "work_of_separation_normalized": _var((), work / w_unit,
                                             "W / W_K, W_K = 2 pi a0^2 dgamma", "1"),
    }


def _coords(params: BrushParams, steps: int, snapshots: int,
            step_name: str) -> dict[str, xr.Variable]:
    """Coordinates of every curve file: step, element centres, snapshot."""
    coord = (np.arange(params.grid) + 0.5) * params.h
    return {
        "step": _var("step", np.arange(steps, dtype=np.int32), step_name, "1"),
        "y": _var("y", coord, "element centre y", "m"),
        "x": _var("x", coord, "element centre x", "m"),
        "snapshot": _var("snapshot", np.arange(snapshots, dtype=np.int32),
                        "contact snapshot index", "1"),
    }


def _run_attrs(params: BrushParams, options: SolverOptions, labels: np.ndarray,
               scales: theory.KendallScales, *, events: int, steps: int, applications: int,
               cg_iterations: int, wall: float, title: str, references: str,
               preconditioner: str, hashed: tuple[dict, ...] = (),
               symmetry_fold: int = 1) -> dict[str, object]:
    """Attributes every curve file carries: inputs, discretisation, cost, provenance.

    ``backend``, ``device_name`` and ``device_memory_bytes`` say where the
    curve ran, ``preconditioner`` which path its solves took (it follows the
    pillar size, the memory budget and, on a device, the card); none of
    them is an input (not in ``parameter_hash``).
    """
    backend = resolve_backend(params.backend)
    return {
        **params.as_attrs(),
        **({"given_inputs": params.given_inputs} if params.given_inputs else {}),
        # netCDF has no boolean attributes
        **{k: int(v) if isinstance(v, bool) else v for k, v in asdict(options).items()},
        "symmetry_fold": symmetry_fold,
        "phi_actual": scales.area / params.side**2,
        "real_contact_area": scales.area,
        "pillar_radius": params.pillar_radius,
        "pillar_radius_elements": params.pillar_radius_elements,
        "side_length": params.side,
        # the units of the normalised columns, on every curve: heights measured
        # in metres are divided by d_K before a run of given heights
        "displacement_unit_d_K": scales.displacement,
        "force_unit_F_K": scales.force,
        "critical_stress": theory.critical_stress(params.e_star, params.dgamma, params.h),
        **geometry_attrs(params, labels),
        "events": events,
        "steps": steps,
        "operator_applications": applications,
        "cg_iterations": cg_iterations,
        "wall_time_s": wall,
        "preconditioner": preconditioner,
        "backend": backend.name,
        # what "auto" resolved to; a device is always double
        "fft_precision": ("single" if backend.on_host and single_transforms(
            params, options, folded=symmetry_fold > 1) else "double"),
        # whose transforms the whole grid ran on (a quadrant: FFTW's DCTs)
        "fft_library_used": fft_library_used(params, options, backend, symmetry_fold),
        # what a rerun's bits hang on besides code and inputs (FFTW's threaded
        # plans; FFTW's wisdom too, which no short digest names: a killed and
        # resumed sweep held other wisdom than one run through, same plans)
        "threads": fft_threads(),
        "device_name": backend.device_name,
        "device_memory_bytes": backend.device_memory_bytes,
        "brushcore_version": version(),
        "git_commit": git_commit(),
        "code_sha256": code_digest(),  # names the code where git cannot (a wheel)
        "source": source(),
        "software_versions": software_versions(),
        "parameter_hash": parameter_hash(params.as_attrs(), asdict(options), *hashed),
        "Conventions": "CF-1.10",
        "title": title,
        "references": references,
        "history": f"{dt.datetime.now(dt.timezone.utc).isoformat(timespec='seconds')} "
                   f"brushcore {version()} simulate",
        "sign_convention": "d > 0 pulls away from the half space; F > 0 is tensile",
        "units_convention": UNITS_CONVENTION,
        "symbols": SYMBOLS,
    }


#: How a protocol is written, for the refusals of other containers.
PROTOCOL_EXAMPLE = "[Waypoint('force', -1.0), Waypoint('separation')]"


def check_arguments(params: object, options: object, protocol: object,
                    progress: object = None) -> None:
    """Refuse arguments `simulate` cannot use, before any work: ``params``
    not a BrushParams (swapped arguments), ``options`` not a SolverOptions
    (None, a dict), ``protocol`` not None or a non-empty list or tuple of
    Waypoint (a bare Waypoint, tuples, dicts) or with a force beyond
    `MAX_ROUGH` F_K (the preload's range: the protocol's tolerance shrinks
    with its load), ``progress`` neither None nor callable.

    Raises
    ------
    ParameterError
        Naming ``params``, ``options``, ``protocol`` or ``progress`` and
        what is allowed.
    """
    if progress is not None and not callable(progress):
        raise ParameterError("progress", _shown(progress),
                             "None or a function progress(events, attached, total)")
    if not isinstance(params, BrushParams):
        raise ParameterError("params", _shown(params), "a BrushParams, the first argument "
                             "(simulate(params, options))")
    if not isinstance(options, SolverOptions):
        raise ParameterError("options", _shown(options),
                             "a SolverOptions: SolverOptions() for the defaults, "
                             "SolverOptions(rtol=1e-6) to change one")
    if protocol is None:
        return
    if isinstance(protocol, Waypoint):
        raise ParameterError("protocol", protocol, f"None or a list of Waypoint, e.g. "
                             f"{PROTOCOL_EXAMPLE}", "a single Waypoint: put it in a list")
    if not isinstance(protocol, (list, tuple)):
        raise ParameterError("protocol", _shown(protocol),
                             f"None or a list of Waypoint, e.g. {PROTOCOL_EXAMPLE}")
    if not protocol:
        raise ParameterError("protocol", list(protocol), "at least one Waypoint")
    for k, leg in enumerate(protocol):
        if not isinstance(leg, Waypoint):
            raise ParameterError("protocol", _shown(protocol),
                                 f"a list of Waypoint, e.g. {PROTOCOL_EXAMPLE}",
                                 f"element {k} is a {type(leg).__name__}: write "
                                 "Waypoint(kind, value)")
    beyond = load_beyond_range(protocol)
    if beyond:
        raise ParameterError("protocol", _shown(protocol), PROTOCOL_LOADS, beyond)


def preload_contact(ds: xr.Dataset, preload: str, press_hint: str) -> str | None:
    """How far an approach pressed the brush, as one line: "12 of 16 pillars in
    contact at the preload", and where a preload of 0 stopped it at first
    touch with pillars left out, why and ``press_hint`` (``preload``, the
    preload's name, and the hint in the caller's terms: flag or config key);
    None where no approach ran (a pull-off from full contact)."""
    if "pillars_in_contact_at_preload" not in ds:
        return None
    touching = int(ds.pillars_in_contact_at_preload)
    n_pillars = int(ds.attrs["n_pillars"])
    protocol = "protocol_normalized" in ds.attrs
    pressed = protocol or float(ds.attrs.get("preload", 0.0))
    return (f"{touching} of {n_pillars} pillars in contact at the "
            + ("first waypoint" if protocol else "preload" if pressed else "first touch")
            + (f" ({preload} 0 stops the approach there; {press_hint})"
               if touching < n_pillars and not pressed else ""))


def first_waypoint_note(protocol: Sequence[Waypoint], offsets: np.ndarray) -> str:
    """Why a protocol (normalised) may not be what was meant, or "": its first
    waypoint pulls from the first touch of a brush that touches there with
    its highest pillars only.

    A protocol starts where the highest element touches, d = max z (offsets
    z_i [d_K], `element_offsets`).  A flat brush touches everywhere at once
    and may be pulled from there; any other pulls on what touched (off it,
    where the load exceeds what those pillars hold): meant so, or a preload
    of the wrong sign (a lab's ``force:2`` for ``force:-2``), which
    `simulate` warns about.
    """
    if not len(protocol) or not offsets.size or np.ptp(offsets) == 0:
        return ""
    first, touch = protocol[0], float(np.max(offsets))
    hint = ("pulls on the pillars that touch there, not on the brush pressed on (a "
            "preload P is force:-P)")
    if first.kind == "force" and first.value > 0:
        return (f"waypoint 0 is a tensile force of {first.value:g} F_K: from the first "
                f"touch, where only the highest pillars touch, it {hint}")
    # the offsets passed through metres: a d given as the first touch itself is no pull
    if first.kind == "displacement" and first.value > touch + 1e-9 * max(1.0, abs(touch)):
        return (f"waypoint 0, displacement {first.value:g} d_K, lies above the first touch "
                f"at d = {touch:.4g} d_K and {hint}; d is measured from the plane where a "
                "pillar of height 0 touches, and a smaller d presses")
    return ""


def common_height_note(protocol: Sequence[Waypoint], heights: np.ndarray | None) -> str:
    """Why given heights [d_K] may not be what a protocol's displacement
    waypoints assume, or "": their mean lies beyond 1 d_K and three times
    their spread.  A common height only moves where d = 0 lies, which the
    forces ignore but an absolute displacement does not (a lab's heights of
    7.6 d_K made "displacement:1.7" a press to 8 F_K)."""
    if heights is None or not any(w.kind == "displacement" for w in protocol):
        return ""
    mean, spread = float(np.mean(heights)), float(np.std(heights))
    if abs(mean) <= max(1.0, 3.0 * spread):
        return ""
    return (f"the heights given have a mean of {mean:.4g} d_K against a spread of "
            f"{spread:.3g}: displacement waypoints are absolute, from the plane where a "
            "pillar of height 0 touches, so a common height moves them (give heights as "
            "offsets from their mean)")


class FirstTouchWarning(UserWarning):
    """An approach at preload 0 stopped at first touch with pillars out of
    contact (heights, roughness or a gap map): a pull-off of the few that
    touched.  The command and the workflow's jobs say it in their own words
    (`preload_contact`) and filter this."""


def check_protocol_preload(preload: float, protocol: object) -> None:
    """Refuse a preload [F_K] beside a protocol, whose first waypoint is the load."""
    if protocol is not None and preload != 0:
        raise ParameterError("preload", preload,
                             "0 when a protocol is given (its first waypoint is the load)")


def _shown(value: object) -> object:
    """A value for a refusal: itself if short, else its type."""
    text = repr(value)
    return value if len(text) <= 80 else f"<{type(value).__name__}>"


def own_labels(params: BrushParams, labels: object = None) -> np.ndarray:
    """The label map of ``params`` (`build_labels`), refusing any other map handed in.

    A caller that built the map already (the CLI prints what it realised)
    may pass it; building it again costs under 0.1 s even at 2048^2.  Any
    other map would run a brush that ``params`` and the curve's
    ``parameter_hash`` do not describe; a layout of one's own is a file
    layout (``layout="file"``, `brushcore.file_params`).

    Raises
    ------
    ParameterError
        For ``labels`` when it differs from ``build_labels(params)``, and as
        `build_labels` for a layout that cannot be built.
    """
    built = build_labels(params)
    if labels is None:
        return built
    try:
        given = np.asarray(labels)
        same = given.shape == built.shape and bool(np.array_equal(given, built))
    except (TypeError, ValueError):  # ragged lists and other non-arrays
        given, same = None, False
    if not same:
        shown = (f"<{type(labels).__name__}>" if given is None or given.ndim != 2 else
                 f"<{given.shape[0]} x {given.shape[1]} map"
                 + (f", {np.count_nonzero(given != built)} elements differing from "
                    "build_labels(params)>" if given.shape == built.shape else ">"))
        raise ParameterError(
            "labels", shown,
            "None or the map build_labels(params) gives (a "
            f"{built.shape[0]} x {built.shape[1]} map of {params.n_pillars} pillars)",
            "another map would run a brush the parameters and parameter_hash do not "
            "describe; a layout of one's own goes through layout='file' "
            "(brushcore.file_params)")
    return built


#: The papers every curve file cites.
REFERENCES = ("He, Li & Popov, Lubricants 8 (2020) 94; Pohrt & Popov, "
              "Facta Univ. Mech. Eng. 13 (2015) 3")
#: What a rough, graded or preloaded curve cites besides: the group's follow-up
#: work the project's design notes name for these brushes.
ROUGH_REFERENCE = "He, Li & Popov, J. Adhesion (2021), doi:10.1080/00218464.2021.1939017"


def simulate(params: BrushParams, options: SolverOptions = SolverOptions(),
             progress: Progress | None = None, labels: np.ndarray | None = None,
             protocol: Sequence[Waypoint] | None = None,
             backend: str | None = None) -> xr.Dataset:
    """Pull-off curve, adhesive force and work of separation as a Dataset.

    ``labels`` (optional) is the label map ``params`` builds, for a caller that
    built it already: any other map is refused (`own_labels`).  ``backend``
    ("cpu" or "gpu"), when given, overrides ``params.backend``; "gpu" needs
    CuPy and a visible CUDA device, checked before any work (ParameterError
    naming what is missing).  GPU curves agree with CPU ones within CG
    tolerance, not bit for bit, and solve the whole grid (no symmetry fold).

    A flat brush (`BrushParams.is_flat`) without ``protocol`` is the flat
    pull-off from full contact.  Otherwise the brush is approached from
    first touch to ``params.preload`` and retracted until it has let go,
    or follows ``protocol``: waypoints whose values are normalised, forces
    in F_K (a preload P is ``Waypoint("force", -P)``) and displacements in
    d_K, the units of the curve's normalised variables.  Such a curve holds
    the flat pull-off's variables (same names, units and meaning, over both
    branches of the loop) and, per step, ``branch`` (waypoint index, -1 at
    first touch), ``direction`` (-1 approach, 0 first touch, +1 retraction)
    and ``retraction`` (1 on the last retraction branch, where
    ``adhesive_force`` and ``work_of_separation`` = integral of max(F, 0) dd
    are taken); per pillar also its height and kbar; and the scalars
    ``dissipated_energy`` (the integral of F dd over the whole protocol: the
    energy dissipated where it ends in separation, else that plus the elastic
    energy stored at its end) and
    ``pillars_in_contact_at_preload``.

    Per pillar (dimension ``pillar``, label order: attribute ``pillar_order``)
    the file holds the centroid (``pillar_y``, ``pillar_x``), the force at
    F_ad (``pillar_force_at_adhesive_force``, summing to F_ad) and the d at
    which the pillar let go (``pillar_let_go_displacement``).

    Signs: d > 0 pulls the brush away, F > 0 is tensile.  Normalised values
    follow the paper (eqs. 20-24) with A the discretised real contact area.

    Parameters
    ----------
    params : the brush (geometry, stiffness, heights, preload)
    options : solver tolerances and switches (default `SolverOptions()`)
    progress : called as progress(events, attached, total) after each event:
        events so far, and the elements (not pillars) in contact out of all
        pillar elements; ``attached`` falls on retraction and grows on an
        approach.  None (default) prints nothing; the CLI's display shows
        100 * attached / total
    labels : the label map ``params`` builds (`build_labels`), or None; any
        other map is refused: a layout of one's own goes through
        ``layout="file"``
    protocol : waypoints, normalised (above); None for the default
    backend : "cpu" or "gpu", overriding ``params.backend``

    Raises
    ------
    ParameterError
        Before any solve, for arguments of the wrong kind (``params``,
        ``options``, ``protocol``, ``progress``: `check_arguments`), a
        force waypoint beyond 1e3 F_K, a layout or
        discretisation that cannot run, ``labels`` other than the
        parameters' own map, an empty protocol or a missing GPU.
    """
    check_arguments(params, options, protocol, progress)
    if backend is not None:
        params = replace(params, backend=backend)
    resolve_backend(params.backend)  # a missing CuPy or card fails before any work
    labels = own_labels(params, labels)
    if protocol is not None or not params.is_flat:
        return _simulate_protocol(params, options, progress, labels, protocol)
    t0 = time.perf_counter()
    detach, curve, applications = run(params, options, progress, labels)
    wall = time.perf_counter() - t0
    h = params.h
    scales = unit_scales(params, labels)  # the pillar elements, as detach >= 0
    fs, ds_, ws = scales.force, scales.displacement, scales.work
    area = curve.attached_elements * h * h
    i_max = int(np.argmax(curve.force))
    f_ad = float(curve.force[i_max])
    work = positive_work(curve.displacement, curve.force)  # as a protocol's branch
    # on element counts: halfway areas tie exactly (1963.5 between 1964 and
    # 1963), and h^2 in metres rounded the tie to another step than h = 1
    snaps = snapshot_steps(curve.attached_elements, curve.force)
    pillar = detach >= 0
    states = np.where(pillar[None], (detach[None] > snaps[:, None, None]).astype(np.int8),
                      np.int8(-1)).astype(np.int8)
    # The step without a pillar's last element: the same d as a protocol's let-go.
    last = np.zeros(params.n_pillars, dtype=np.int64)
    np.maximum.at(last, labels[pillar], detach[pillar])

    data = {
        **_step_variables(curve.displacement, curve.force, area, curve.attached_pillars,
                          ds_, fs, "pull-off displacement d"),
        "detachment_step": _filled("detachment_step", ("y", "x"), detach,
                                   "first step at which the element is detached",
                                   comment="-1 (the fill) outside pillars"),
        "contact_snapshot": _filled("contact_snapshot", ("snapshot", "y", "x"), states,
                                    "contact state",
                                    flag_values=np.array([-1, 0, 1], dtype=np.int8),
                                    flag_meanings="no_pillar detached attached"),
        "snapshot_step": _filled("snapshot_step", "snapshot", snaps, "step of the snapshot"),
        "snapshot_label": xr.Variable("snapshot", np.array(SNAPSHOT_LABELS),
                                      {"long_name": "stage of the pull-off"}),
        **_pillar_results(labels, h, curve.pillar_force_at_peak, curve.displacement[last]),
        **_result_variables(f_ad, float(curve.displacement[i_max]), work, fs, ws,
                            "adhesive force (maximum tensile force)",
                            "work of separation, integral of max(F, 0) dd"),
    }
    attrs = _run_attrs(params, options, labels, scales, events=curve.events,
                       steps=int(curve.displacement.size), applications=applications,
                       cg_iterations=curve.cg_iterations, wall=wall,
                       title="Adhesive pull-off of a spring-mounted pillar brush",
                       references=REFERENCES, preconditioner=curve.preconditioner,
                       symmetry_fold=curve.symmetry_fold)
    attrs["pillar_order"] = PILLAR_ORDER
    return mark_element_units(xr.Dataset(data, coords={
        **_coords(params, curve.displacement.size, snaps.size,
                  "step of the pull-off (one per solve)"),
        "pillar": _pillar_coord(params.n_pillars)}, attrs=attrs))


def _simulate_protocol(params: BrushParams, options: SolverOptions, progress: Progress | None,
                       labels: np.ndarray, protocol: Sequence[Waypoint] | None) -> xr.Dataset:
    """`simulate` of a protocol run on the label map `own_labels` returned."""
    backend = resolve_backend(params.backend)
    t0 = time.perf_counter()
    inputs = pillar_inputs(params, labels)
    scales = inputs.scales
    fs, ds_ = scales.force, scales.displacement
    if protocol is None:
        waypoints = preload_protocol(inputs.preload)
    else:
        check_protocol_preload(params.preload, protocol)
        offsets = element_offsets(labels, inputs.heights, inputs.gap_map) / ds_
        for note in (first_waypoint_note(protocol, offsets),
                     common_height_note(protocol, params.heights)):
            if note:  # each its own: a pull from the first touch and absolute heights
                warnings.warn(note, stacklevel=3)
        waypoints = tuple(Waypoint(w.kind, w.value * (fs if w.kind == "force" else ds_))
                          for w in protocol)
    # How far loads and height scatter (given heights or a gap map) reach, in
    # F_K and d_K (a displacement waypoint is no measure: soft springs stretch
    # far at small stresses; the loads it reaches are checked after the run).
    forces = [abs(w.value) / fs for w in waypoints if w.kind == "force"]
    gaps = (0.0 if inputs.gap_map is None
            else float(np.std(np.asarray(inputs.gap_map)[labels >= 0])) / ds_)
    span = max([params.preload, params.roughness, float(np.std(inputs.heights)) / ds_, gaps,
                *forces])
    asked = options
    stiffness = stiffness_span(inputs.compliance, labels, params.h, params.e_star)
    options = spring_options(load_options(asked, span), stiffness)  # the attrs record it

    def run_at(opts: SolverOptions):
        return run_protocol_curve(
            params, waypoints, opts, heights=inputs.heights, gap_map=inputs.gap_map,
            compliance=inputs.compliance, progress=progress, labels=labels)

    _, op, curve, applications = run_at(options)
    reached = float(np.max(np.abs(curve.force), initial=0.0)) / fs
    # Displacement waypoints that pressed harder than the span said (forces
    # and scatter are known before: a preload's own load is no news, nor a
    # few per cent more, which moves rtol by as little)
    pressed = any(w.kind == "displacement" for w in waypoints) and reached > 1.01 * span
    if pressed:
        tighter = spring_options(load_options(asked, reached), stiffness)
        if tighter.rtol < options.rtol:
            warnings.warn(
                f"the protocol's displacement waypoints reached a load of {reached:.3g} F_K, "
                f"beyond the {max(span, LOAD_SPAN):g} its tolerance was set for: run again at "
                f"rtol {tighter.rtol:.3g} (the loop energy's error grows as rtol x load^2; "
                f"a force waypoint sets it before the run)", stacklevel=3)
            options = tighter
            first = applications  # the cost counts both runs, as wall_time_s does
            _, op, curve, applications = run_at(options)
            applications += first
        if reached > 1.01 * MAX_ROUGH:
            warnings.warn(
                f"the protocol's displacement waypoints reached a load of {reached:.3g} F_K, "
                f"beyond the range of loads whose energies the solver's tolerance keeps "
                f"accurate ({PROTOCOL_LOADS}): read its dissipated energy with care",
                stacklevel=3)
    wall = time.perf_counter() - t0
    h = params.h
    ws = scales.work
    d, f = curve.displacement, curve.force
    peaks = [_retraction_peak(d, f, first, last) for first, last in curve.pulls]
    i_max, f_ad, d_ad, work = peaks[-1] if peaks else (-1, math.nan, math.nan, math.nan)
    if not peaks:  # a loading-only protocol is legitimate, but say why F_ad is NaN
        warnings.warn("the protocol never retracts: adhesive_force and work_of_separation "
                      "are NaN (end it with a separation waypoint for a pull-off: "
                      "Waypoint('separation'), or 'separation' in --protocol or a config's "
                      "protocol)",
                      stacklevel=3)
    # ... from contact: a leg that starts apart has nothing to let go of
    unreached = [k for k, w in enumerate(waypoints) if w.kind == "force" and w.value > 0
                 and curve.attached_elements[curve.waypoint_step[k]] == 0
                 and (k == 0 or curve.attached_elements[curve.waypoint_step[k - 1]] > 0)]
    if unreached:  # a tensile target beyond the pull-off: the leg ended at separation
        warnings.warn("; ".join(f"waypoint {k} (force:{waypoints[k].value / fs:g}) was not "
                                f"reached" for k in unreached)
                      + ": the brush let go first, at its adhesive force, and the leg ended "
                      "at separation (F = 0)", stacklevel=3)
    empty = [k for k, (first, _) in enumerate(curve.pulls)
             if curve.attached_elements[first] == 0]
    if empty:  # e.g. force:2 after a complete pull-off: nothing to pull on
        warnings.warn(f"retraction {', '.join(map(str, empty))} starts with no pillar in "
                      "contact: its adhesive_force is NaN and its work 0 (a force:-P waypoint "
                      "before it presses the brush on again)", stacklevel=3)
    compressive = [k for k, peak in enumerate(peaks)
                   if not math.isfinite(peak[1]) and k not in empty]
    if compressive:  # an unloading that never pulls: no F_ad to speak of
        warnings.warn(f"retraction {', '.join(map(str, compressive))} stays compressive: "
                      "its adhesive_force is NaN and its work 0 (it unloads without "
                      "pulling)", stacklevel=3)
    if peaks and math.isfinite(f_ad) and curve.attached_elements[curve.pulls[-1][1]] > 0:
        warnings.warn("the last retraction ends in contact: adhesive_force is the largest "
                      "force it reached, not a pull-off (end the protocol with a "
                      "separation waypoint for one: Waypoint('separation'), or "
                      "'separation' in --protocol or a config's protocol)", stacklevel=3)
    dissipated = loop_energy(d, f)
    area = curve.attached_elements * h * h
    n_pillars = op.n_pillars
    pillar_of = backend.to_host(op.pillar_of)

    def on_grid(values: np.ndarray, fill, dtype) -> np.ndarray:
        out = np.full(labels.size, fill, dtype=dtype)
        out[op.elements] = values
        return out.reshape(labels.shape)

    # Contact maps at every waypoint and at F_ad (1 attached, 0 not, -1 no pillar).
    masks = list(curve.attached_at_waypoint) + [curve.attached_at_peak]
    names = _snapshot_names(protocol)
    steps = list(curve.waypoint_step) + [i_max]
    states = np.stack([on_grid(m.astype(np.int8), -1, np.int8) for m in masks])
    if i_max < 0:  # no tensile step, no map of one (`FILL_VALUES`)
        states[-1] = FILL_VALUES["contact_snapshot"]
    preload_step = int(curve.waypoint_step[0])
    in_contact = int(np.count_nonzero(np.bincount(
        pillar_of, weights=curve.attached_at_waypoint[0], minlength=n_pillars)))
    if protocol is None and not params.preload and in_contact < n_pillars:
        warnings.warn(FirstTouchWarning(
            f"{in_contact} of {n_pillars} pillars in contact at the first touch: preload 0 "
            "stops the approach there, so only those pull off (BrushParams(preload=P), P in "
            "F_K, presses the brush on)"), stacklevel=3)
    pillar_force = curve.pillar_force_at_peak
    if pillar_force is None or i_max < 0:
        pillar_force = np.full(n_pillars, np.nan)

    data = {
        **_step_variables(d, f, area, curve.attached_pillars, ds_, fs,
                          "displacement d of the backing plate"),
        "branch": _filled("branch", "step", curve.branch.astype(np.int32),
                          "index of the protocol waypoint being followed",
                          comment="-1 (the fill) at first touch"),
        "direction": _var("step", curve.direction.astype(np.int8), "direction of motion",
                         "1", flag_values=np.array([APPROACH, START, RETRACT], dtype=np.int8),
                         flag_meanings="approach first_touch retraction"),
        "retraction": _var("step", curve.retraction.astype(np.int8),
                          "step belongs to the last retraction branch", "1",
                          flag_values=np.array([0, 1], dtype=np.int8),
                          flag_meanings="other last_retraction"),
        "attachment_step": _filled("attachment_step", ("y", "x"),
                                   on_grid(curve.attach_step, -1, np.int32),
                                   "last step at which the element attached",
                                   comment="-1 (the fill) outside pillars or never in contact"),
        "detachment_step": _filled("detachment_step", ("y", "x"),
                                   on_grid(curve.detach_step, -1, np.int32),
                                   "first step without the element after its last detachment",
                                   comment="-1 (the fill) outside pillars, never detached"),
        "contact_snapshot": _filled("contact_snapshot", ("snapshot", "y", "x"), states,
                                    "contact state",
                                    flag_values=np.array([-1, 0, 1], dtype=np.int8),
                                    flag_meanings="no_pillar detached attached",
                                    comment="-2 (the fill): a stage the run never reached"),
        "snapshot_step": _filled("snapshot_step", "snapshot", np.asarray(steps, dtype=np.int32),
                                 "step of the snapshot",
                                 comment="-1 (the fill): a stage the run never reached"),
        "snapshot_label": xr.Variable("snapshot", np.array(names),
                                      {"long_name": "stage of the protocol"}),
        # Given arrays as given, bit for bit (x * d_K / d_K is not always x):
        # `BrushParams.from_curve` rebuilds them and their inputs_digest.
        **_pillar_variables(labels, h, inputs.heights,
                            (inputs.heights / ds_ if params.heights is None
                             else np.array(params.heights)),
                            inputs.kbar, pillar_force, curve.let_go),
        **_result_variables(f_ad, d_ad, work, fs, ws,
                            "adhesive force (maximum tensile force of the last retraction)",
                            "work of separation, integral of max(F, 0) dd over the last "
                            "retraction"),
        **_pull_variables(d, f, area, curve.pulls, peaks, fs, ws),
        # the energy lost only from first touch to separation: a protocol that
        # ends pressed holds elastic energy besides (12.1 W_K after a press alone)
        "dissipated_energy": _var((), dissipated, "integral of F dd over the protocol",
                                  "J", comment=DISSIPATED_COMMENT),
        "dissipated_energy_normalized": _var((), dissipated / ws,
                                            "integral of F dd over the protocol / W_K", "1",
                                            comment=DISSIPATED_COMMENT),
        "pillars_in_contact_at_preload": _var((), np.int32(in_contact),
                                             "pillars with attached elements at the end of "
                                             "the first waypoint", "1"),
        "contact_area_at_preload": _var((), float(area[preload_step]),
                                       "real contact area at the end of the first waypoint",
                                       "m2"),
    }
    if inputs.gap_map is not None:
        data["gap_map"] = _var(("y", "x"), inputs.gap_map, "extra gap of each element", "m")
        # In d_K, as BrushParams(gap_map=...) and --gap-map take it back.
        data["gap_map_normalized"] = _var(("y", "x"), np.array(params.gap_map),
                                          "extra gap of each element / d_K", "1")
    attrs = _run_attrs(params, options, labels, scales, events=curve.events,
                       steps=int(d.size), applications=applications,
                       cg_iterations=curve.cg_iterations, wall=wall,
                       title="Approach, preload and pull-off of a rough, graded pillar brush",
                       references=f"{REFERENCES}; {ROUGH_REFERENCE}",
                       preconditioner=op.preconditioner,
                       hashed=({"protocol": [(w.kind, w.value) for w in waypoints]},))
    attrs.update({
        "preload_force": float(-waypoints[0].value) if waypoints[0].kind == "force" else 0.0,
        "protocol": "; ".join(f"{w.kind} {w.value:.9g}" for w in waypoints),
        "pillar_order": PILLAR_ORDER,
    })
    if protocol is not None:  # as given (normalised), the form --protocol and the config take
        attrs["protocol_normalized"] = protocol_text(protocol)
    return mark_element_units(xr.Dataset(data, coords={
        **_coords(params, d.size, len(steps), "step of the protocol (one per event or solve)"),
        "pillar": _pillar_coord(n_pillars),
        "pull": _var("pull", np.arange(len(peaks), dtype=np.int32),
                     "retraction branch index, in order", "1"),
    }, attrs=attrs))


def _retraction_peak(d: np.ndarray, f: np.ndarray, first: int,
                     last: int) -> tuple[int, float, float, float]:
    """Step, force [N], displacement [m] and work [J] of the pull-off of the
    retraction over steps first ... last: its largest tensile force and the
    integral of max(F, 0) dd.  One that stays compressive has no tensile
    force (NaN, step -1) and no work (0).
    """
    on = slice(first, last + 1)
    if f[on].max() > 0:
        i_max = first + int(np.argmax(f[on]))
        return i_max, float(f[i_max]), float(d[i_max]), positive_work(d[on], f[on])
    return -1, math.nan, math.nan, 0.0


def _pull_variables(d: np.ndarray, f: np.ndarray, area: np.ndarray, pulls: np.ndarray,
                    peaks: list[tuple[int, float, float, float]], f_unit: float,
                    w_unit: float) -> dict[str, xr.Variable]:
    """Per retraction branch (dimension ``pull``, in order): its steps, F_ad,
    the d of F_ad, W, the contact left at its end and the energy of its cycle.

    A pull's cycle runs from the end of the previous pull (first touch for
    the first) to the end of this one, so over a protocol that ends on a
    retraction the cycles' energies sum to the dissipated energy.
    """
    first = pulls[:, 0].astype(np.int32)
    last = pulls[:, 1].astype(np.int32)
    starts = np.concatenate([[0], last[:-1]]).astype(int)
    cycle = np.array([loop_energy(d[a:b + 1], f[a:b + 1]) for a, b in zip(starts, last)])
    f_ad, d_ad, work = np.array([peak[1:] for peak in peaks], dtype=float).reshape(-1, 3).T
    return {
        "pull_first_step": _var("pull", first, "first step of the retraction branch", "1"),
        "pull_last_step": _var("pull", last, "last step of the retraction branch", "1"),
        "pull_adhesive_force": _var("pull", f_ad, "maximum tensile force of the retraction "
                                    "branch", "N"),
        "pull_adhesive_force_normalized": _var("pull", f_ad / f_unit, "F_ad / F_K of the "
                                               "retraction branch", "1"),
        "pull_displacement_at_adhesive_force": _var("pull", d_ad, "d at the branch's maximum "
                                                    "tensile force", "m"),
        "pull_work_of_separation": _var("pull", work, "integral of max(F, 0) dd over the "
                                        "retraction branch", "J",
                                        comment="segments split where F crosses 0 "
                                        "(brushcore.positive_work): clipping F at 0 "
                                        "before a trapezoid sum over-counts a branch "
                                        "that starts under load"),
        "pull_work_of_separation_normalized": _var("pull", work / w_unit, "W / W_K of the "
                                                   "retraction branch", "1"),
        "pull_contact_area_at_end": _var("pull", area[last], "real contact area at the "
                                         "branch's last step", "m2"),
        "pull_cycle_energy": _var("pull", cycle, "integral of F dd from the end of the "
                                  "previous retraction branch (first touch) to the end of "
                                  "this one", "J",
                                  comment="sums to dissipated_energy; a branch that ends "
                                  "under load also holds the elastic energy stored there"),
        "pull_cycle_energy_normalized": _var("pull", cycle / w_unit, "cycle energy / W_K", "1"),
    }


def _snapshot_names(protocol: Sequence[Waypoint] | None) -> list[str]:
    """Labels of a protocol's contact snapshots: one per waypoint (as the user
    gave it, normalised), then "maximum force"; the default protocol's two
    waypoints read "preload" and "separated"."""
    if protocol is None:
        return ["preload", "separated", "maximum force"]
    return [f"waypoint {k}: {w.kind}" + (f" {w.value:g}" if w.kind != "separation" else "")
            for k, w in enumerate(protocol)] + ["maximum force"]


#: The attribute ``pillar_order`` of every curve file: what the dimension ``pillar`` follows.
PILLAR_ORDER = ("label order: regular brushes row-major, pillar i*sqrt(N)+j at "
                "((i+1/2) L/sqrt(N), (j+1/2) L/sqrt(N)) along (y, x); random brushes "
                "in placement order; other layouts as labelled; pillar_y, pillar_x "
                "give every pillar's centroid")


def _pillar_coord(n_pillars: int) -> xr.Variable:
    """The coordinate ``pillar``: pillar index in label order."""
    return _var("pillar", np.arange(n_pillars, dtype=np.int32), "pillar index (label order)",
                "1")


def _pillar_results(labels: np.ndarray, h: float, force_at_peak: np.ndarray,
                    let_go: np.ndarray) -> dict[str, xr.Variable]:
    """Per pillar, in every curve file: centroid [m] and area [m^2] of its
    elements, force at F_ad [N] and the displacement at which it let go [m]."""
    centre = pillar_centroids(labels, h)
    area = pillar_element_counts(labels, len(centre)) * (h * h)
    return {
        "pillar_y": _var("pillar", centre[:, 0], "pillar centroid y", "m"),
        "pillar_x": _var("pillar", centre[:, 1], "pillar centroid x", "m"),
        "pillar_area": _var("pillar", area, "pillar contact area (its elements)", "m2"),
        "pillar_force_at_adhesive_force": _var("pillar", force_at_peak,
                                              "pillar force at F_ad (tensile positive)", "N"),
        "pillar_let_go_displacement": _var("pillar", let_go,
                                          "d at which the pillar's last element detached",
                                          "m", comment="NaN: never in contact, or still attached at "
                                          "the end"),
    }


def _pillar_variables(labels: np.ndarray, h: float, heights: np.ndarray,
                      normalized: np.ndarray, kbar: np.ndarray, force_at_peak: np.ndarray,
                      let_go: np.ndarray) -> dict[str, xr.Variable]:
    """Per pillar in a protocol's file: `_pillar_results` with the protrusion
    [m] and ``normalized`` [d_K], and k̄, after the centroid and area."""
    results = _pillar_results(labels, h, force_at_peak, let_go)
    centroid = {name: results.pop(name) for name in ("pillar_y", "pillar_x", "pillar_area")}
    return {
        **centroid,
        "pillar_height": _var("pillar", heights, "pillar protrusion z_p "
                             "(larger reaches the substrate first)", "m"),
        "pillar_height_normalized": _var("pillar", normalized, "z_p / d_K", "1"),
        "pillar_kbar": _var("pillar", kbar, "pillar spring stiffness k_p / (E* L)", "1"),
        **results,
    }
