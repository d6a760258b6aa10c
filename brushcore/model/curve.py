"""One pull-off from parameters to an xarray Dataset (the curve file content):
`simulate` checks its arguments, runs `brushcore.model.solve` and describes
what it returns in the terms of `brushcore.model.curve_format`."""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import xarray as xr

from brushcore.model.curve_format import (DISSIPATED_COMMENT, FILL_VALUES, PILLAR_ORDER,
                                          REFERENCES, ROUGH_REFERENCE, SNAPSHOT_LABELS,
                                          cf_variable, curve_coords, filled_variable,
                                          mark_element_units, pillar_coord, pillar_results,
                                          pillar_variables, pull_variables, result_variables,
                                          run_attrs, snapshot_names, snapshot_steps,
                                          step_variables)
from brushcore.model.inputs import PROTOCOL_LOADS, load_beyond_range, protocol_text
from brushcore.model.layout import build_labels
from brushcore.model.params import MAX_ROUGH, BrushParams
from brushcore.model.rough import pillar_inputs
from brushcore.model.scales import unit_scales
from brushcore.model.solve import (LOAD_SPAN, element_offsets, load_options,
                                   run, run_protocol_curve, spring_options,
                                   stiffness_span)
from brushcore.numerics.platform.backend import resolve_backend
from brushcore.numerics.options import REQUESTED_RTOL, SolverOptions
from brushcore.numerics.events.waypoints import (APPROACH, RETRACT, START, Waypoint,
                                                 loop_energy, positive_work, preload_protocol)
from brushcore.numerics.events.pulloff import Progress
from brushcore.validation import ParameterError, suggest_keywords

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


@suggest_keywords
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
        **step_variables(curve.displacement, curve.force, area, curve.attached_pillars,
                         ds_, fs, "pull-off displacement d"),
        "detachment_step": filled_variable("detachment_step", ("y", "x"), detach,
                                           "first step at which the element is detached",
                                           comment="-1 (the fill) outside pillars"),
        "contact_snapshot": filled_variable("contact_snapshot", ("snapshot", "y", "x"), states,
                                            "contact state",
                                            flag_values=np.array([-1, 0, 1], dtype=np.int8),
                                            flag_meanings="no_pillar detached attached"),
        "snapshot_step": filled_variable("snapshot_step", "snapshot", snaps,
                                         "step of the snapshot"),
        "snapshot_label": xr.Variable("snapshot", np.array(SNAPSHOT_LABELS),
                                      {"long_name": "stage of the pull-off"}),
        **pillar_results(labels, h, curve.pillar_force_at_peak, curve.displacement[last]),
        **result_variables(f_ad, float(curve.displacement[i_max]), work, fs, ws,
                           "adhesive force (maximum tensile force)",
                           "work of separation, integral of max(F, 0) dd"),
    }
    attrs = run_attrs(params, options, labels, scales, events=curve.events,
                      steps=int(curve.displacement.size), applications=applications,
                      cg_iterations=curve.cg_iterations, wall=wall,
                      title="Adhesive pull-off of a spring-mounted pillar brush",
                      references=REFERENCES, preconditioner=curve.preconditioner,
                      symmetry_fold=curve.symmetry_fold)
    attrs["pillar_order"] = PILLAR_ORDER
    return mark_element_units(xr.Dataset(data, coords={
        **curve_coords(params, curve.displacement.size, snaps.size,
                       "step of the pull-off (one per solve)"),
        "pillar": pillar_coord(params.n_pillars)}, attrs=attrs))


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
    names = snapshot_names(protocol)
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
        **step_variables(d, f, area, curve.attached_pillars, ds_, fs,
                         "displacement d of the backing plate"),
        "branch": filled_variable("branch", "step", curve.branch.astype(np.int32),
                                  "index of the protocol waypoint being followed",
                                  comment="-1 (the fill) at first touch"),
        "direction": cf_variable(
            "step", curve.direction.astype(np.int8), "direction of motion", "1",
            flag_values=np.array([APPROACH, START, RETRACT], dtype=np.int8),
            flag_meanings="approach first_touch retraction"),
        "retraction": cf_variable("step", curve.retraction.astype(np.int8),
                                  "step belongs to the last retraction branch", "1",
                                  flag_values=np.array([0, 1], dtype=np.int8),
                                  flag_meanings="other last_retraction"),
        "attachment_step": filled_variable(
            "attachment_step", ("y", "x"), on_grid(curve.attach_step, -1, np.int32),
            "last step at which the element attached",
            comment="-1 (the fill) outside pillars or never in contact"),
        "detachment_step": filled_variable(
            "detachment_step", ("y", "x"), on_grid(curve.detach_step, -1, np.int32),
            "first step without the element after its last detachment",
            comment="-1 (the fill) outside pillars, never detached"),
        "contact_snapshot": filled_variable(
            "contact_snapshot", ("snapshot", "y", "x"), states, "contact state",
            flag_values=np.array([-1, 0, 1], dtype=np.int8),
            flag_meanings="no_pillar detached attached",
            comment="-2 (the fill): a stage the run never reached"),
        "snapshot_step": filled_variable(
            "snapshot_step", "snapshot", np.asarray(steps, dtype=np.int32),
            "step of the snapshot", comment="-1 (the fill): a stage the run never reached"),
        "snapshot_label": xr.Variable("snapshot", np.array(names),
                                      {"long_name": "stage of the protocol"}),
        # Given arrays as given, bit for bit (x * d_K / d_K is not always x):
        # `BrushParams.from_curve` rebuilds them and their inputs_digest.
        **pillar_variables(labels, h, inputs.heights,
                           (inputs.heights / ds_ if params.heights is None
                             else np.array(params.heights)),
                           inputs.kbar, pillar_force, curve.let_go),
        **result_variables(f_ad, d_ad, work, fs, ws,
                           "adhesive force (maximum tensile force of the last retraction)",
                           "work of separation, integral of max(F, 0) dd over the last "
                           "retraction"),
        **pull_variables(d, f, area, curve.pulls, peaks, fs, ws),
        # the energy lost only from first touch to separation: a protocol that
        # ends pressed holds elastic energy besides (12.1 W_K after a press alone)
        "dissipated_energy": cf_variable((), dissipated, "integral of F dd over the protocol",
                                         "J", comment=DISSIPATED_COMMENT),
        "dissipated_energy_normalized": cf_variable(
            (), dissipated / ws, "integral of F dd over the protocol / W_K", "1",
            comment=DISSIPATED_COMMENT),
        "pillars_in_contact_at_preload": cf_variable(
            (), np.int32(in_contact), "pillars with attached elements at the end of the first "
            "waypoint", "1"),
        "contact_area_at_preload": cf_variable(
            (), float(area[preload_step]), "real contact area at the end of the first waypoint",
            "m2"),
    }
    if inputs.gap_map is not None:
        data["gap_map"] = cf_variable(("y", "x"), inputs.gap_map, "extra gap of each element", "m")
        # In d_K, as BrushParams(gap_map=...) and --gap-map take it back.
        data["gap_map_normalized"] = cf_variable(("y", "x"), np.array(params.gap_map),
                                                 "extra gap of each element / d_K", "1")
    attrs = run_attrs(params, options, labels, scales, events=curve.events,
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
        # ``rtol`` is what ran, tightened above; a rerun must be given this
        # (`SolverOptions.from_curve`), or it would tighten again
        REQUESTED_RTOL: asked.rtol,
    })
    if protocol is not None:  # as given (normalised), the form --protocol and the config take
        attrs["protocol_normalized"] = protocol_text(protocol)
    return mark_element_units(xr.Dataset(data, coords={
        **curve_coords(params, d.size, len(steps),
                       "step of the protocol (one per event or solve)"),
        "pillar": pillar_coord(n_pillars),
        "pull": cf_variable("pull", np.arange(len(peaks), dtype=np.int32),
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
