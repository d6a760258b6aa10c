"""Per-pillar inputs of a rough and graded brush, from its parameters.

Heights, stiffnesses and gap maps are given (or drawn) in normalised units;
this module turns them into the solver's units once the label map, and
with it the discretised pillar area A that defines d_K and F_K, is known.
Random draws use their own streams of ``seed`` ([seed, 1] heights, [seed, 2]
stiffness), so they do not depend on the random layout's draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brushcore.model import theory
from brushcore.model.draws import gaussian_heights, lognormal_kbar
from brushcore.model.params import BrushParams
from brushcore.model.scales import unit_scales
from brushcore.validation import ParameterError


@dataclass(frozen=True)
class PillarInputs:
    """What the protocol engine needs beyond the label map.

    Attributes
    ----------
    heights : protrusion z_p per pillar [length], label order
    kbar : normalised stiffness per pillar (inf: rigid)
    compliance : h^2 / k_p per pillar [length / stress] (0: rigid)
    gap_map : extra gap per element [length], shape (n, n), or None
    scales : F_K, d_K, W_K and A of the discretised area (`unit_scales`)
    preload : P [force]
    """

    heights: np.ndarray
    kbar: np.ndarray
    compliance: np.ndarray
    gap_map: np.ndarray | None
    scales: theory.KendallScales
    preload: float


def pillar_inputs(params: BrushParams, labels: np.ndarray) -> PillarInputs:
    """Heights, stiffnesses, gap map and units of a brush on its label map.

    Raises
    ------
    ParameterError
        When given per-pillar arrays do not match the pillars the layout
        realised (``params.n_pillars`` is checked already; a label map
        handed in may differ).
    """
    n = int(labels.max()) + 1
    for name in ("heights", "kbar_values"):
        given = getattr(params, name)
        if given is not None and len(given) != n:
            raise ParameterError(name, f"<{len(given)} values>",
                                 f"one value per pillar of the layout ({n})")
    scales = unit_scales(params, labels)
    d_unit, f_unit = scales.displacement, scales.force
    if params.heights is not None:
        heights = np.asarray(params.heights, dtype=float) * d_unit
    else:
        heights = gaussian_heights(params.roughness, n, params.seed) * d_unit
    if params.kbar_values is not None:
        kbar = np.asarray(params.kbar_values, dtype=float)
    else:
        kbar = lognormal_kbar(params.kbar, params.kbar_spread, n, params.seed)
    k = theory.stiffness_from_kbar(kbar, params.e_star, params.side)
    with np.errstate(divide="ignore"):
        compliance = np.where(np.isinf(k), 0.0, params.h**2 / k)
    gap = None if params.gap_map is None else np.asarray(params.gap_map) * d_unit
    return PillarInputs(heights, kbar, compliance, gap, scales,
                        params.preload * f_unit)


def pillar_centroids(labels: np.ndarray, h: float) -> np.ndarray:
    """Centroid (y, x) of each pillar's elements [length], shape (N, 2)."""
    n_pillars = int(labels.max()) + 1
    iy, ix = np.nonzero(labels >= 0)
    lab = labels[iy, ix]
    count = np.bincount(lab, minlength=n_pillars)
    y = np.bincount(lab, weights=iy + 0.5, minlength=n_pillars) / count
    x = np.bincount(lab, weights=ix + 0.5, minlength=n_pillars) / count
    return np.column_stack([y, x]) * h
