"""What a curve file holds and says: the CF description of a curve.

Units and symbols, the integer variables' fill values, the step, result,
pull and pillar variables with their long names and units, the
coordinates and the attributes every curve file carries (inputs,
discretisation, cost, provenance).  `brushcore.model.curve.simulate`
computes a curve and describes it with these; `brushcore.data` reads and
writes files by the same constants.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np
import xarray as xr

from brushcore.model import theory
from brushcore.model.labelmap import count_touching_pairs, pillar_element_counts
from brushcore.model.lattices import hexagonal_fill, hexagonal_lattice
from brushcore.model.layout import random_gap, smallest_radius_elements
from brushcore.model.layout_file import pillar_shapes
from brushcore.model.params import BrushParams
from brushcore.model.provenance import (code_digest, git_commit, parameter_hash,
                                        software_versions, source, version)
from brushcore.model.rough import pillar_centroids
from brushcore.model.solve import fft_library_used, single_transforms
from brushcore.numerics.platform.backend import resolve_backend
from brushcore.numerics.platform.threads import fft_threads
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.events.waypoints import Waypoint, loop_energy


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
    (`layout.random_gap`), a file's digest and its pillars' shapes in words
    (`layout_file.pillar_shapes`).

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
        attrs["pillar_shapes"] = pillar_shapes(params.layout_file)  # shape says "disc"
    return attrs


#: What ``dissipated_energy`` is where a protocol does not end in separation.
DISSIPATED_COMMENT = ("the energy dissipated where the protocol runs from first touch to "
                      "separation; a protocol that ends in contact adds the elastic energy "
                      "stored at its end")


def cf_variable(dims, data, name: str, units: str, **extra) -> xr.Variable:
    """A CF variable: values with long_name, units and any extra attributes."""
    return xr.Variable(dims, data, {"long_name": name, "units": units, **extra})


def filled_variable(name: str, dims, data: np.ndarray, long_name: str, **extra) -> xr.Variable:
    """A dimensionless integer variable ``name`` whose `FILL_VALUES` entry
    means "none": declared as its netCDF _FillValue (`brushcore.data.io`
    writes it), kept as a number in memory."""
    var = cf_variable(dims, data, long_name, "1", **extra)
    var.encoding["_FillValue"] = fill_value(name, var.dtype)
    return var


def step_variables(displacement: np.ndarray, force: np.ndarray, area: np.ndarray,
                   attached_pillars: np.ndarray, d_unit: float, f_unit: float,
                   displacement_name: str) -> dict[str, xr.Variable]:
    """The curve itself, per step, in SI and normalised (every curve file's)."""
    return {
        "displacement": cf_variable("step", displacement, displacement_name, "m"),
        "force": cf_variable("step", force, "tensile normal force F", "N"),
        "contact_area": cf_variable("step", area, "real contact area", "m2"),
        "attached_pillars": cf_variable("step", attached_pillars.astype(np.int32),
                                        "pillars with attached elements", "1"),
        "displacement_normalized": cf_variable("step", displacement / d_unit,
                                               "d / d_K, d_K = sqrt(2 pi dgamma a0 / E*)", "1"),
        "force_normalized": cf_variable("step", force / f_unit,
                                        "F / F_K, F_K = sqrt(8 pi E* dgamma a0^3)", "1"),
    }


def result_variables(f_ad: float, d_ad: float, work: float, f_unit: float, w_unit: float,
                     force_name: str, work_name: str) -> dict[str, xr.Variable]:
    """F_ad, the d it is reached at and W, in SI and normalised (every curve file's)."""
    return {
        "adhesive_force": cf_variable((), f_ad, force_name, "N"),
        "adhesive_force_normalized": cf_variable((), f_ad / f_unit, "F_ad / F_K", "1"),
        "displacement_at_adhesive_force": cf_variable((), d_ad, "d at the adhesive force", "m"),
        "work_of_separation": cf_variable((), work, work_name, "J"),
        "work_of_separation_normalized": cf_variable((), work / w_unit,
                                                     "W / W_K, W_K = 2 pi a0^2 dgamma", "1"),
    }


def curve_coords(params: BrushParams, steps: int, snapshots: int,
                 step_name: str) -> dict[str, xr.Variable]:
    """Coordinates of every curve file: step, element centres, snapshot."""
    coord = (np.arange(params.grid) + 0.5) * params.h
    return {
        "step": cf_variable("step", np.arange(steps, dtype=np.int32), step_name, "1"),
        "y": cf_variable("y", coord, "element centre y", "m"),
        "x": cf_variable("x", coord, "element centre x", "m"),
        "snapshot": cf_variable("snapshot", np.arange(snapshots, dtype=np.int32),
                                "contact snapshot index", "1"),
    }


def run_attrs(params: BrushParams, options: SolverOptions, labels: np.ndarray,
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


#: The papers every curve file cites.
REFERENCES = ("He, Li & Popov, Lubricants 8 (2020) 94; Pohrt & Popov, "
              "Facta Univ. Mech. Eng. 13 (2015) 3")
#: What a rough, graded or preloaded curve cites besides: the group's follow-up
#: work the project's design notes name for these brushes.
ROUGH_REFERENCE = "He, Li & Popov, J. Adhesion (2021), doi:10.1080/00218464.2021.1939017"


def pull_variables(d: np.ndarray, f: np.ndarray, area: np.ndarray, pulls: np.ndarray,
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
        "pull_first_step": cf_variable("pull", first, "first step of the retraction branch", "1"),
        "pull_last_step": cf_variable("pull", last, "last step of the retraction branch", "1"),
        "pull_adhesive_force": cf_variable("pull", f_ad, "maximum tensile force of the retraction "
                                           "branch", "N"),
        "pull_adhesive_force_normalized": cf_variable("pull", f_ad / f_unit, "F_ad / F_K of the "
                                                      "retraction branch", "1"),
        "pull_displacement_at_adhesive_force": cf_variable(
            "pull", d_ad, "d at the branch's maximum tensile force", "m"),
        "pull_work_of_separation": cf_variable("pull", work, "integral of max(F, 0) dd over the "
                                               "retraction branch", "J",
                                               comment="segments split where F crosses 0 "
                                               "(brushcore.positive_work): clipping F at 0 "
                                               "before a trapezoid sum over-counts a branch "
                                               "that starts under load"),
        "pull_work_of_separation_normalized": cf_variable("pull", work / w_unit, "W / W_K of the "
                                                          "retraction branch", "1"),
        "pull_contact_area_at_end": cf_variable("pull", area[last], "real contact area at the "
                                                "branch's last step", "m2"),
        "pull_cycle_energy": cf_variable("pull", cycle, "integral of F dd from the end of the "
                                         "previous retraction branch (first touch) to the end of "
                                         "this one", "J",
                                         comment="sums to dissipated_energy; a branch that ends "
                                         "under load also holds the elastic energy stored there"),
        "pull_cycle_energy_normalized": cf_variable("pull", cycle / w_unit,
                                                    "cycle energy / W_K", "1"),
    }


def snapshot_names(protocol: Sequence[Waypoint] | None) -> list[str]:
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


def pillar_coord(n_pillars: int) -> xr.Variable:
    """The coordinate ``pillar``: pillar index in label order."""
    return cf_variable("pillar", np.arange(n_pillars, dtype=np.int32),
                       "pillar index (label order)", "1")


def pillar_results(labels: np.ndarray, h: float, force_at_peak: np.ndarray,
                   let_go: np.ndarray) -> dict[str, xr.Variable]:
    """Per pillar, in every curve file: centroid [m] and area [m^2] of its
    elements, force at F_ad [N] and the displacement at which it let go [m]."""
    centre = pillar_centroids(labels, h)
    area = pillar_element_counts(labels, len(centre)) * (h * h)
    return {
        "pillar_y": cf_variable("pillar", centre[:, 0], "pillar centroid y", "m"),
        "pillar_x": cf_variable("pillar", centre[:, 1], "pillar centroid x", "m"),
        "pillar_area": cf_variable("pillar", area, "pillar contact area (its elements)", "m2"),
        "pillar_force_at_adhesive_force": cf_variable(
            "pillar", force_at_peak, "pillar force at F_ad (tensile positive)", "N"),
        "pillar_let_go_displacement": cf_variable(
            "pillar", let_go, "d at which the pillar's last element detached", "m",
            comment="NaN: never in contact, or still attached at the end"),
    }


def pillar_variables(labels: np.ndarray, h: float, heights: np.ndarray,
                     normalized: np.ndarray, kbar: np.ndarray, force_at_peak: np.ndarray,
                     let_go: np.ndarray) -> dict[str, xr.Variable]:
    """Per pillar in a protocol's file: `pillar_results` with the protrusion
    [m] and ``normalized`` [d_K], and k̄, after the centroid and area."""
    results = pillar_results(labels, h, force_at_peak, let_go)
    centroid = {name: results.pop(name) for name in ("pillar_y", "pillar_x", "pillar_area")}
    return {
        **centroid,
        "pillar_height": cf_variable("pillar", heights, "pillar protrusion z_p "
                                     "(larger reaches the substrate first)", "m"),
        "pillar_height_normalized": cf_variable("pillar", normalized, "z_p / d_K", "1"),
        "pillar_kbar": cf_variable("pillar", kbar, "pillar spring stiffness k_p / (E* L)", "1"),
        **results,
    }
