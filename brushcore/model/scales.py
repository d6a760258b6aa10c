"""The units of a brush's normalised results, known before its run.

F_K, d_K and W_K follow from the real contact area A, which the grid
realises (the pillar elements), not from the requested phi: heights
measured in metres are divided by this d_K, loads by this F_K.
"""

from __future__ import annotations

import numpy as np

from brushcore.model import theory
from brushcore.model.layout import build_labels
from brushcore.model.params import BrushParams
from brushcore.validation import require


def unit_scales(params: BrushParams, labels: np.ndarray | None = None) -> theory.KendallScales:
    """F_K, d_K, W_K and A of a brush on its grid, as its curve file will record them.

    Parameters
    ----------
    params : the brush
    labels : its label map (`build_labels`), or None to build it

    Raises
    ------
    ParameterError
        As `build_labels`, where the grid does not draw the brush.
    """
    require(isinstance(params, BrushParams), "params", type(params).__name__,
            "a BrushParams (the brush)")
    labels = build_labels(params) if labels is None else labels
    area = float(np.count_nonzero(labels >= 0)) * params.h * params.h
    return theory.kendall_scales(area, params.e_star, params.dgamma)
