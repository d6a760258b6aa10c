"""Collect one-curve files into the analysis-ready sweep dataset (``sweep.nc``).

One curve file holds one pull-off simulation (one layout, N, kbar, seed,
grid).  `build_sweep` reads and checks them all (`brushcore.data.curve_set`) and lays
the scalars out on the full (layout, n_pillars, kbar, seed, grid) product,
NaN where a combination was not run, with the force-displacement curves
NaN-padded along ``step``.  ``grid`` (elements per side n) is a dimension even
when a sweep has one grid, so that mesh-refinement studies
(`brushcore.data.convergence`) and single-grid sweeps share one layout;
`brushcore.data.views.finest_grid` reduces it to one value per case for the
figures and tables.  Pillar shapes other than discs and rough brushes add
the dimensions ``shape`` and roughness, preload, kbar_spread, only when such
a case ran; `brushcore.data.views.flat_slice` gives the flat disc brushes
the paper's figures show.  Curves of generated brushes asked for different
filling factors add the dimension ``phi`` (the phi asked for; a file brush
sits at its file's), and `brushcore.data.views.phi_slice` gives one of them;
a sweep of one phi keeps it as the attribute ``phi`` alone.
Contact snapshots are large, so only a chosen subset of cases (of one grid) keeps
them, stacked along a ``case`` dimension.  The result opens with plain
``xarray.open_dataset``; `encoding` gives the compression to write it with.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np
import xarray as xr

from brushcore.model import provenance
from brushcore.model.params import narrowest_radius
from brushcore.model.curve_format import FILL_VALUES, fill_value, mark_element_units
from brushcore.model.layout_file import FILE_LAYOUT_PREFIX
from brushcore.model.shapes import parse_shape_label
from brushcore.data.curve_set import (IN_MEMORY_PATTERN, PHI_DIM, ROUGH_DIMS, SHAPE_DIM,
                                      SWEEP_DIMS,
                                      CaseKey, check_one_brush_per_case,
                                      check_one_file_per_layout, common_attr, file_sha256,
                                      given_inputs, load_curves)
# the sweep's own names, as its readers and the workflow take them from here
from brushcore.data.curve_set import GRID_DIM, AggregationError, case_key  # noqa: F401
from brushcore.data.io import write_dataset_atomic

#: Order of the layout coordinate (others follow, sorted).
LAYOUT_ORDER = ("regular", "hexagonal", "random")
#: Coordinates along SHAPE_DIM: its labels' numbers.
SHAPE_NUMBERS = ("shape_aspect", "shape_orientation")
#: Scalars of rough runs, NaN for flat curve files, kept when ROUGH_DIMS are
#: (some case is rough or a brush as made) or a protocol ran.
ROUGH_SCALARS = ("dissipated_energy_normalized", "pillars_in_contact_at_preload")
#: The realised height scatter of each case (`realised_height_sd`), beside ROUGH_SCALARS.
HEIGHT_SD = "pillar_height_sd_normalized"
#: Why a ROUGH_SCALARS value is NaN where the variable has values elsewhere.
FLAT_PULL_OFF_NAN = ("NaN for a flat brush at preload 0 without a protocol: it pulls off from "
                     "full contact with no approach (every pillar in contact; its loop is the "
                     "retraction alone, so its dissipated energy equals W)")

#: Scalar variables copied from each curve file.
SCALAR_VARIABLES = (
    "adhesive_force_normalized",
    "work_of_separation_normalized",
    "adhesive_force",
    "work_of_separation",
    "displacement_at_adhesive_force",
)
#: Curve-file attributes promoted to sweep variables: name -> (units, long_name).
ATTRIBUTE_SCALARS = {
    "events": ("1", "events of the run: detachments, and attachments on an approach"),
    "operator_applications": ("1", "applications of the elastic + spring operator"),
    "cg_iterations": ("1", "conjugate-gradient iterations"),
    "wall_time_s": ("s", "wall time of the simulation"),
    "phi_actual": ("1", "filling factor A / L^2 realised on the grid"),
    "real_contact_area": ("m2", "real contact area A"),
    "pillar_radius_elements": ("1", "pillar radius a_p / h (elements a radius spans)"),
    "smallest_radius_elements": ("1", "the narrowest pillar's radius / h (an ellipse's "
                                      "semi-minor axis, a table's or map's smallest pillar)"),
    "touching_pillar_pairs": ("1", "pillar pairs whose footprints share an element edge"),
    # the normalisation's units per case (A is the case's own): F = F_bar F_K, d = d_bar d_K
    "force_unit_F_K": ("N", "Kendall's force F_K of the compact punch of area A"),
    "displacement_unit_d_K": ("m", "Kendall's displacement d_K of the compact punch of area A"),
    # dimensional values are in the inputs' units: with h = 1 those of each grid's own h
    "side_length": ("m", "side L = n h of the square holding the pillars"),
    # 4: applications counted on one quadrant (a mirror-symmetric brush), 1: whole grid
    "symmetry_fold": ("1", "symmetry fold of the solve: operator_applications count "
                           "applications on 1/symmetry_fold of the padded grid"),
}
#: Counts, stored as int64 with the fill -1 (NaN in memory where a case never ran).
COUNT_VARIABLES = ("events", "operator_applications", "cg_iterations",
                   "touching_pillar_pairs", "symmetry_fold", "n_steps", "attached_pillars")
#: Curve-file attributes every curve of a sweep must share (the physics) ...
SHARED_ATTRIBUTES = ("min_gap", "e_star", "dgamma", "h", "units_convention", "symbols",
                     "protocol_normalized")
#: ... and those that may differ (numerics): kept as attributes, distinct values joined by "; ".
SOLVER_ATTRIBUTES = ("rtol", "max_iter", "tie_rtol", "lookahead", "cascade", "symmetry",
                     "precision", "fft_precision", "fft_library", "fft_library_used",
                     "preconditioner", "threads",
                     "early_decisions",
                     "settle_decisions", "allow_coarse")
#: Per retraction branch of a sweep whose curves follow a given protocol
#: (attribute ``protocol_normalized``), NaN-padded along ``pull``.
PULL_VARIABLES = (
    "pull_adhesive_force_normalized",
    "pull_work_of_separation_normalized",
    "pull_cycle_energy_normalized",
    "pull_contact_area_at_end",
)
#: Per-step curves, NaN-padded to the longest curve of the sweep.
CURVE_VARIABLES = (
    "displacement",
    "force",
    "displacement_normalized",
    "force_normalized",
    "contact_area",
    "attached_pillars",
)


def _shared_attr(curves: dict[CaseKey, tuple[Path, xr.Dataset]], name: str) -> object:
    """`common_attr` of every curve, but for ``min_gap``: only a random draw
    keeps it, so it must agree among the random brushes alone; a lattice
    records 1 (and did, but from Python before 2026-12-07, whatever it was
    given: such a curve's min_gap disagreed with the rest and stopped the sweep)."""
    if name != "min_gap":
        return common_attr(curves, name)
    drawn = {k: c for k, c in curves.items() if c[1].attrs.get("layout") == "random"}
    if drawn:
        return common_attr(drawn, name)
    return 1.0 if any(name in c.attrs for _, c in curves.values()) else None


def case_dims(keys: Iterable[CaseKey]) -> tuple[str, ...]:
    """The case dimensions and grid, plus PHI_DIM when the generated brushes
    (not files, whose phi is their own) were asked for more than one phi,
    SHAPE_DIM when any pillar is not a disc and ROUGH_DIMS when any case is
    not flat."""
    keys = list(keys)
    phi = (PHI_DIM,) if len(generated_phis(keys)) > 1 else ()
    shape = (SHAPE_DIM,) if any(k.shape != "disc" for k in keys) else ()
    rough = () if all(k.is_flat for k in keys) else ROUGH_DIMS
    return SWEEP_DIMS + phi + shape + rough


def generated_phis(keys: Iterable[CaseKey]) -> list[float]:
    """The filling factors the generated brushes (not files) of ``keys`` were asked for, sorted."""
    return sorted({float(k.phi) for k in keys
                   if k.phi is not None and not k.layout.startswith(FILE_LAYOUT_PREFIX)})


def _case_coords(keys: Iterable[CaseKey]) -> dict[str, np.ndarray]:
    keys = list(keys)
    layouts = [lay for lay in LAYOUT_ORDER if any(k.layout == lay for k in keys)]
    layouts += sorted({k.layout for k in keys} - set(LAYOUT_ORDER))
    coords = {
        "layout": np.array(layouts, dtype=object),
        "n_pillars": np.array(sorted({k.n_pillars for k in keys}), dtype=np.int64),
        "kbar": np.array(sorted({k.kbar for k in keys}), dtype=np.float64),
        "seed": np.array(sorted({k.seed for k in keys}), dtype=np.int64),
        "grid": np.array(sorted({k.grid for k in keys}), dtype=np.int64),
        # a file brush's own phi too: it sits there, NaN at the phis asked of the others
        PHI_DIM: np.array(sorted({float(k.phi) for k in keys if k.phi is not None}),
                          dtype=np.float64),
    }
    for dim in ROUGH_DIMS:
        coords[dim] = np.array(sorted({getattr(k, dim) for k in keys}), dtype=np.float64)
    shapes = sorted({k.shape for k in keys}, key=lambda label: (label != "disc", label))
    coords[SHAPE_DIM] = np.array(shapes, dtype=object)
    return coords


def _index(coords: dict[str, np.ndarray], key: CaseKey,
           dims: Sequence[str] = SWEEP_DIMS) -> tuple[int, ...]:
    return tuple(int(np.flatnonzero(coords[dim] == getattr(key, dim))[0]) for dim in dims)


def snapshot_filter(
    keep: Iterable[tuple[str, int]], *, all_below_bytes: int, total_bytes: int
) -> Callable[[CaseKey], bool]:
    """Which cases keep their contact snapshots.

    Parameters
    ----------
    keep : (layout, n_pillars) pairs whose snapshots are always kept (Fig. 5).
    all_below_bytes : keep every case's snapshots if they need less than this.
    total_bytes : size all snapshots would need [bytes].
    """
    if total_bytes < all_below_bytes:
        return lambda key: True
    wanted = {(str(layout), int(n)) for layout, n in keep}
    return lambda key: (key.layout, key.n_pillars) in wanted


def build_sweep(
    paths: Sequence[str | Path | xr.Dataset],
    *,
    keep_snapshots: Iterable[tuple[str, int]] = (("regular", 256),),
    all_snapshots_below_mb: float = 64.0,
    expected: Sequence[tuple[CaseKey, float]] | None = None,
) -> xr.Dataset:
    """Aggregate curve files into one sweep dataset.

    Parameters
    ----------
    paths : curve files written by `brushcore.data.io.write_curve`, or the
        curves themselves (`brushcore.simulate`'s Datasets; a notebook's
        study needs no files), in any mix.
    keep_snapshots : (layout, n_pillars) whose contact snapshots are kept;
        their finest grid is the one whose maps the sweep keeps (maps of
        different grids cannot share (y, x)).
    all_snapshots_below_mb : keep all snapshots when they total less [MiB].
    expected : per path, the (case, phi) it must hold (`load_curves`).

    Returns
    -------
    xarray.Dataset
        Scalars on (layout, n_pillars, kbar, seed, grid) (+ phi where the
        generated brushes' curves differ in it, + shape, + the rough dims,
        see `case_dims`); curves on the same dims plus ``step``; snapshots of one grid on (case, snapshot, y, x);
        provenance attrs.

    Raises
    ------
    AggregationError
        Naming the offending file when one cannot be read or cases clash.
    """
    curves = load_curves(paths, expected)
    check_one_file_per_layout(curves)
    check_one_brush_per_case(curves)
    # A file brush has its file's phi (each case's phi_actual); the attribute is
    # that of the generated brushes, whose phi the figures' theory lines take.
    generated = {k: pc for k, pc in curves.items() if pc[1].attrs.get("layout") != "file"}
    coords = _case_coords(curves)
    # several: the coordinate phi says each case's, and the attribute is NaN
    phi = (common_attr(generated, "phi") if generated else None) \
        if len(generated_phis(curves)) < 2 else math.nan
    # A brush as made is not flat whatever its coordinates: the rough dims say so.
    given = {key: given_inputs(curve) for key, (_, curve) in curves.items()}
    dims = tuple(dict.fromkeys(case_dims(curves) + (ROUGH_DIMS if any(given.values()) else ())))
    shape = tuple(len(coords[d]) for d in dims)
    n_steps = max(curve.sizes["step"] for _, curve in curves.values())
    # Descriptions from a protocol's curve where there is one: its meanings
    # (W over the last retraction, steps of approach and retraction) hold
    # for a flat pull-off too, not the other way round.
    first = next((c for _, c in curves.values() if "retraction" in c),
                 next(iter(curves.values()))[1])
    protocol = common_attr(curves, "protocol_normalized")  # None: approach to each preload
    rough_scalars = ROUGH_SCALARS if ROUGH_DIMS[0] in dims or protocol else ()
    pull_names = PULL_VARIABLES if protocol else ()
    n_pulls = max((curve.sizes.get("pull", 0) for _, curve in curves.values()), default=0)

    data: dict[str, xr.DataArray] = {}
    scalars = {name: np.full(shape, np.nan)
               for name in (*SCALAR_VARIABLES, *ATTRIBUTE_SCALARS, *rough_scalars)}
    scalars["n_steps"] = np.full(shape, np.nan)
    lines = {name: np.full((*shape, n_steps), np.nan) for name in CURVE_VARIABLES}
    pulls = {name: np.full((*shape, n_pulls), np.nan) for name in pull_names}
    heights_sd = np.full(shape, np.nan) if rough_scalars else None
    for key, (_, curve) in curves.items():
        at = _index(coords, key, dims)
        for name in (*SCALAR_VARIABLES, *rough_scalars):
            if name in curve:
                scalars[name][at] = float(curve[name])
        if heights_sd is not None:  # what a seed drew: S is only its expectation
            heights_sd[at] = realised_height_sd(curve)
        for name in ATTRIBUTE_SCALARS:
            scalars[name][at] = _attribute(curve, name)
        scalars["n_steps"][at] = curve.sizes["step"]
        for name in CURVE_VARIABLES:
            values = np.asarray(curve[name].values, dtype=np.float64)
            lines[name][at][: values.size] = values
        for name in pull_names:
            values = np.asarray(curve[name].values, dtype=np.float64)
            pulls[name][at][: values.size] = values

    for name in SCALAR_VARIABLES:
        data[name] = xr.DataArray(scalars[name], dims=dims, attrs=dict(first[name].attrs))
    for name in rough_scalars:
        attrs = next((dict(c[name].attrs) for _, c in curves.values() if name in c), {})
        if any(name not in c for _, c in curves.values()):  # say why, or NaN reads as lost
            attrs["comment"] = FLAT_PULL_OFF_NAN
        data[name] = xr.DataArray(scalars[name], dims=dims, attrs=attrs)
    if heights_sd is not None:
        data[HEIGHT_SD] = xr.DataArray(heights_sd, dims=dims, attrs={
            "units": "1", "long_name": "standard deviation of the brush's pillar heights / d_K "
                                       "as drawn or given (population SD; 0 where the heights "
                                       "are equal, a gap map's offsets aside)"})
    for name, (units, long_name) in ATTRIBUTE_SCALARS.items():
        data[name] = xr.DataArray(
            scalars[name], dims=dims, attrs={"units": units, "long_name": long_name}
        )
    data["displacement_at_adhesive_force_normalized"] = xr.DataArray(
        scalars["displacement_at_adhesive_force"] / scalars["displacement_unit_d_K"],
        dims=dims, attrs={"units": "1", "long_name": "d at the adhesive force / d_K"})
    data["n_steps"] = xr.DataArray(
        scalars["n_steps"], dims=dims,
        attrs={"units": "1", "long_name": "valid entries along step (rest is NaN padding)"},
    )
    for name in CURVE_VARIABLES:
        data[name] = xr.DataArray(
            lines[name], dims=(*dims, "step"), attrs=dict(first[name].attrs)
        )
    for name in pull_names:
        data[name] = xr.DataArray(pulls[name], dims=(*dims, "pull"), attrs=dict(first[name].attrs))
    data.update(_snapshots(curves, keep_snapshots, all_snapshots_below_mb, dims))

    sweep = xr.Dataset(data, coords=_coordinate_arrays(coords, dims))
    if protocol and "preload" in sweep.coords:  # it read as an unloaded brush
        sweep["preload"].attrs["comment"] = ("0: the protocol gives the loads (attribute "
                                             "protocol_normalized)")
    if pull_names:  # as the curve files have it: which retraction, in order
        index = np.arange(n_pulls, dtype=np.int32)
        sweep = sweep.assign_coords(pull=xr.Variable("pull", index, {
            "units": "1", "long_name": "retraction branch index, in order (0 = the first)"}))
    # The stacked snapshot cases are labels, not data: make them coordinates.
    sweep = sweep.set_coords([n for n in sweep.data_vars if n.startswith("case_")])
    sweep.attrs = _provenance(curves, phi=phi)
    for name in SHARED_ATTRIBUTES:
        value = _shared_attr(curves, name)
        if value is not None:
            sweep.attrs[name] = value
    for name in SOLVER_ATTRIBUTES:
        values = {str(c.attrs[name]): c.attrs[name] for _, c in curves.values()
                  if name in c.attrs}
        if values:
            sweep.attrs[name] = (next(iter(values.values())) if len(values) == 1
                                 else "; ".join(sorted(values)))
    return mark_element_units(sweep.assign({**_varying_settings(curves, coords, dims),
                                            **_given_inputs(given, coords, dims)}))


def realised_height_sd(curve: xr.Dataset) -> float:
    """Population standard deviation of a curve's pillar heights [d_K]: what
    its seed drew (16 pillars at S = 0.3: 0.370 and 0.157 for seeds 0 and 1)
    or what it was given; 0 for a flat pull-off, whose file has no heights."""
    if "pillar_height_normalized" not in curve:
        return 0.0
    return float(np.std(np.asarray(curve["pillar_height_normalized"].values, dtype=float)))


def _given_inputs(given: dict[CaseKey, str], coords: dict[str, np.ndarray],
                  dims: Sequence[str]) -> dict[str, xr.DataArray]:
    """``given_inputs`` per case (``given``: `given_inputs` of each case's
    curve) where some curve's brush was given per-pillar or per-element
    arrays: its roughness and kbar_spread coordinates are 0 (nothing drawn),
    yet it is not flat.  Nothing where no curve was given any."""
    if not any(given.values()):
        return {}
    values = np.full(tuple(len(coords[d]) for d in dims), "", dtype=object)
    for key, text in given.items():
        values[_index(coords, key, dims)] = text
    return {"given_inputs": xr.DataArray(
        values.astype(str), dims=dims,
        attrs={"long_name": "arrays the brush was given (heights, kbar_values, gap_map; "
                            "space-separated, '' for none)"})}


def _varying_settings(curves: dict, coords: dict[str, np.ndarray],
                      dims: Sequence[str]) -> dict[str, xr.DataArray]:
    """``run_{name}`` per case for each solver setting, the commit and the
    libraries that differ between curves (a protocol's rtol shrinks with its
    load; regular brushes run double and random ones float32; a resumed sweep
    may mix versions or machines): the joined attribute says that they
    differ, this says where.
    Text, "" where no curve ran."""
    out = {}
    for name in (*SOLVER_ATTRIBUTES, "git_commit", "code_sha256", "software_versions"):
        if len({str(c.attrs.get(name, "")) for _, c in curves.values()}) < 2:
            continue
        values = np.full(tuple(len(coords[d]) for d in dims), "", dtype=object)
        for key, (_, curve) in curves.items():
            values[_index(coords, key, dims)] = str(curve.attrs.get(name, ""))
        out[f"run_{name}"] = xr.DataArray(
            values.astype(str), dims=dims,
            attrs={"long_name": f"{name} the curve ran with (it differs between curves; "
                                "'' where none ran)"})
    return out


def _attribute(curve: xr.Dataset, name: str) -> float:
    """A numeric curve attribute, NaN when absent.

    Curve files written before ``pillar_radius_elements`` was recorded give
    it from ``pillar_radius`` / ``h``; those written before
    ``smallest_radius_elements`` give it from their shape (an ellipse's
    semi-minor axis r / sqrt(aspect), as `BrushParams.narrowest_radius_elements`),
    and a file layout's the mean radius (its pillars are not recorded).
    """
    if name == "smallest_radius_elements" and name not in curve.attrs:
        return narrowest_radius(_attribute(curve, "pillar_radius_elements"),
                                str(curve.attrs.get("shape", "disc")),
                                float(curve.attrs.get("aspect", 1.0)))
    if name == "pillar_radius_elements" and name not in curve.attrs:
        a = curve.attrs
        return float(a["pillar_radius"]) / float(a["h"]) if "pillar_radius" in a and "h" in a \
            else math.nan
    return float(curve.attrs.get(name, np.nan))


def _coordinate_arrays(coords: dict[str, np.ndarray],
                       dims: Sequence[str] = SWEEP_DIMS) -> dict[str, xr.DataArray]:
    attrs = {
        "layout": {"long_name": "pillar layout"},
        "n_pillars": {"units": "1", "long_name": "number of pillars N"},
        "kbar": {"units": "1", "long_name": "normalised spring stiffness k / (E* L)"},
        "seed": {"units": "1", "long_name": "seed of the random layout and of drawn heights and "
                                          "stiffnesses (0 for flat lattice brushes)"},
        "grid": {"units": "1", "long_name": "elements per side n of the L x L square"},
        "roughness": {"units": "1", "long_name": "std of pillar heights / d_K"},
        "preload": {"units": "1", "long_name": "preload / F_K"},
        "kbar_spread": {"units": "1", "long_name": "coefficient of variation of kbar"},
        PHI_DIM: {"units": "1", "long_name": "filling factor A / L^2 asked for (a file brush's: "
                                            "its file's; phi_actual is the one realised)"},
        # a label, like layout: no units
        SHAPE_DIM: {"long_name": "pillar cross-section: disc, square[_orientation in "
                                 "degrees] or ellipse{aspect}_{orientation in degrees}"},
    }
    out = {d: xr.DataArray(coords[d], dims=d, attrs=attrs[d]) for d in dims}
    for d in ("layout", SHAPE_DIM):
        if d in out:
            out[d] = out[d].astype(str)
    if SHAPE_DIM in out:  # the label's numbers, for selecting and plotting by them
        fields = [parse_shape_label(str(label)) for label in coords[SHAPE_DIM]]
        aspect, orientation = SHAPE_NUMBERS
        out[aspect] = xr.DataArray(
            np.array([f["aspect"] for f in fields]), dims=SHAPE_DIM,
            attrs={"units": "1", "long_name": "major / minor axis of the pillar (1: disc, "
                                              "square)"})
        out[orientation] = xr.DataArray(
            np.array([f["orientation"] for f in fields]), dims=SHAPE_DIM,
            attrs={"units": "degree", "long_name": "angle from the x axis to a square's side "
                                                   "or an ellipse's major axis"})
    return out


def _snapshots(
    curves: dict[CaseKey, tuple[Path, xr.Dataset]],
    keep: Iterable[tuple[str, int]],
    all_below_mb: float,
    dims: Sequence[str] = SWEEP_DIMS,
) -> dict[str, xr.DataArray]:
    always = {(str(layout), int(n)) for layout, n in keep}  # the Fig. 5 brushes
    with_snaps = {k: c for k, (_, c) in curves.items() if "contact_snapshot" in c}
    if not with_snaps:
        return {}
    total = sum(int(c["contact_snapshot"].size) for c in with_snaps.values())
    wanted = snapshot_filter(always, all_below_bytes=int(all_below_mb * 2**20),
                             total_bytes=total)
    keys = sorted(k for k in with_snaps if wanted(k))
    if not keys:
        return {}
    # Maps of different grids cannot share (y, x): keep one grid's, the
    # finest that the always-kept (Fig. 5) brushes ran on, else the finest.
    figure = [k for k in keys if (k.layout, k.n_pillars) in always]
    finest = max(k.grid for k in (figure or keys))
    keys = [k for k in keys if k.grid == finest]
    n_snap = max(with_snaps[k].sizes["snapshot"] for k in keys)
    ny, nx = with_snaps[keys[0]].sizes["y"], with_snaps[keys[0]].sizes["x"]
    snap = np.full((len(keys), n_snap, ny, nx), FILL_VALUES["contact_snapshot"], dtype=np.int8)
    step = np.full((len(keys), n_snap), FILL_VALUES["snapshot_step"], dtype=np.int32)
    label = np.full((len(keys), n_snap), "", dtype=object)
    detach = np.full((len(keys), ny, nx), FILL_VALUES["detachment_step"], dtype=np.int32)
    for i, key in enumerate(keys):
        c = with_snaps[key]
        m = c.sizes["snapshot"]
        snap[i, :m] = c["contact_snapshot"].values
        step[i, :m] = c["snapshot_step"].values
        label[i, :m] = [str(s) for s in c["snapshot_label"].values]
        if "detachment_step" in c:
            detach[i] = c["detachment_step"].values
    first = next((with_snaps[k] for k in keys if "retraction" in with_snaps[k]),
                 with_snaps[keys[0]])  # descriptions as for the scalars
    extra = dims[len(SWEEP_DIMS):]  # shape and rough dims of the sweep, if any
    dims = ("case", "snapshot")
    out = {
        "contact_snapshot": xr.DataArray(
            snap, dims=(*dims, "y", "x"), attrs={
                **first["contact_snapshot"].attrs,
                "comment": "-2 (the fill): no such snapshot (a case with fewer snapshots than "
                           "the others is padded with such maps, whose snapshot_step is the "
                           "fill too and snapshot_label empty), or a stage the run never "
                           "reached"}
        ),
        "snapshot_step": xr.DataArray(step, dims=dims, attrs=dict(first["snapshot_step"].attrs)),
        "snapshot_label": xr.DataArray(label.astype(str), dims=dims,
                                       attrs={"long_name": "stage of the pull-off or protocol"}),
        # one grid and one h (a shared attribute): the curves' own element centres
        "y": xr.DataArray(first["y"].values, dims="y", attrs=dict(first["y"].attrs)),
        "x": xr.DataArray(first["x"].values, dims="x", attrs=dict(first["x"].attrs)),
        "case_layout": xr.DataArray(np.array([k.layout for k in keys]), dims="case",
                                    attrs={"long_name": "layout of the snapshot case"}),
        "case_n_pillars": xr.DataArray(np.array([k.n_pillars for k in keys]), dims="case",
                                       attrs={"long_name": "N of the snapshot case",
                                              "units": "1"}),
        "case_kbar": xr.DataArray(np.array([k.kbar for k in keys]), dims="case",
                                  attrs={"long_name": "kbar of the snapshot case", "units": "1"}),
        "case_seed": xr.DataArray(np.array([k.seed for k in keys]), dims="case",
                                  attrs={"long_name": "seed of the snapshot case", "units": "1"}),
        "case_grid": xr.DataArray(np.array([k.grid for k in keys]), dims="case",
                                  attrs={"long_name": "grid n of the snapshot case", "units": "1"}),
    }
    for dim in extra:
        units = {} if dim == SHAPE_DIM else {"units": "1"}  # shape is a label
        out[f"case_{dim}"] = xr.DataArray(np.array([getattr(k, dim) for k in keys]), dims="case",
                                          attrs={"long_name": f"{dim} of the snapshot case",
                                                 **units})
    if "detachment_step" in first:
        out["detachment_step"] = xr.DataArray(
            detach, dims=("case", "y", "x"), attrs=dict(first["detachment_step"].attrs)
        )
    return out


def _provenance(
    curves: dict[CaseKey, tuple[Path, xr.Dataset]], *, phi: object
) -> dict[str, object]:
    sources = sorted(((str(path), curve) for path, curve in curves.values()),
                     key=lambda source: source[0])
    files = [name for name, _ in sources]
    hashes = [digest.group(1) if (digest := IN_MEMORY_PATTERN.fullmatch(name))
              else file_sha256(name) for name, _ in sources]
    combined = hashlib.sha256("\n".join(f"{h}  {f}" for f, h in zip(files, hashes)).encode())
    commits = sorted({str(c.attrs.get("git_commit", "unknown")) for _, c in curves.values()})
    # the code itself, which an installed copy's "git unknown" cannot tell apart
    codes = sorted({str(c.attrs.get("code_sha256", "not recorded")) for _, c in curves.values()})
    versions = sorted({str(c.attrs.get("brushcore_version", "unknown")) for _, c in curves.values()})
    # files written before it was recorded are said, not left out
    software = sorted({str(c.attrs.get("software_versions", "not recorded"))
                       for _, c in curves.values()})
    # every paper any curve cites, in the order first met (rough curves cite one
    # more), each once: an older file's shorter form of a reference gives way
    cited = list(dict.fromkeys(ref for _, c in curves.values()
                               for ref in str(c.attrs.get("references", "")).split("; ")
                               if ref))
    cited = [ref for ref in cited if not any(o != ref and o.startswith(ref) for o in cited)]
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    return {
        "title": "brushcore sweep: adhesive pull-off of spring-mounted brushes",
        "Conventions": "CF-1.10",
        "references": "; ".join(cited) or "He, Li & Popov, Lubricants 8 (2020) 94",
        "history": f"{now} aggregated {len(files)} curve files by brushcore.data.aggregate",
        "date_created": now,
        "brushcore_version": provenance.version(),
        "git_commit": provenance.git_commit(),
        # CF: how the data were made, the curves' code, then what gathered them
        "source": f"brushcore simulations (git {', '.join(commits)}), aggregated by "
                  f"{provenance.source()}",
        "simulation_brushcore_versions": ", ".join(versions),
        "simulation_git_commits": ", ".join(commits),
        "simulation_code_sha256": ", ".join(codes),
        "simulation_software_versions": "; ".join(software),
        "grid": np.array(sorted({k.grid for k in curves}), dtype=np.int64),  # every grid run
        "phi": float(phi) if phi is not None else math.nan,
        "source_files": "\n".join(files),
        "source_sha256": "\n".join(hashes),
        "source_digest_sha256": combined.hexdigest(),
    }


#: Where a sweep's curves may not differ unsaid: the code, and the accuracy
#: settings (rtol may, by design: large loads tighten it, `solve.load_options`).
MIXED_ATTRIBUTES = ("simulation_git_commits", "simulation_code_sha256", "precision", "cascade")


def mixed_runs(sweep: xr.Dataset) -> str:
    """What a sweep's curves differ in of `MIXED_ATTRIBUTES`, as "name (values),
    ...", or "" where they agree (curves of two commits, say, before a
    study extrapolates across them)."""
    mixed = [name for name in MIXED_ATTRIBUTES
             if "; " in str(sweep.attrs.get(name, "")) or ", " in str(sweep.attrs.get(name, ""))]
    return ", ".join(f"{name} ({sweep.attrs[name]})" for name in mixed)


def encoding(sweep: xr.Dataset, complevel: int = 4) -> dict[str, dict[str, object]]:
    """netCDF4 encoding: zlib for the padded curves and the snapshots, counts as int64
    (fill -1, read back as NaN), the curves' "none" of snapshots and step maps
    as its fill (`brushcore.model.curve_format.FILL_VALUES`).

    One chunk per curve keeps NaN padding and unrun cases nearly free on disk.
    """
    enc: dict[str, dict[str, object]] = {name: {"_FillValue": None} for name in sweep.coords}
    for name, var in sweep.data_vars.items():
        if name in COUNT_VARIABLES:
            enc[name] = {"dtype": "int64", "_FillValue": np.int64(-1)}
        elif name in FILL_VALUES:  # the curves' "none" (snapshots and step maps)
            enc[name] = {"_FillValue": fill_value(name, var.dtype)}
        whole = {"step", "y", "x"} & set(var.dims)
        if var.dtype.kind not in "fi" or not whole:
            continue  # small scalars and labels: default storage
        chunks = tuple(n if d in whole else 1 for d, n in var.sizes.items())
        enc[name] = {**enc.get(name, {}), "zlib": True, "complevel": complevel,
                     "chunksizes": chunks}
    return enc


def write_sweep(sweep: xr.Dataset, path: str | Path) -> None:
    """Write the sweep to netCDF4 atomically (temporary file + rename)."""
    write_dataset_atomic(sweep, path, encoding(sweep))
