"""brushcore: adhesive pull-off of spring-mounted fibrillar brushes.

Boundary elements on a non-periodic elastic half space (pruned DC-FFT),
pillar springs coupled into the influence operator, preconditioned CG, the
mesh-dependent JKR detachment criterion of Pohrt & Popov (2015), and an
event-driven displacement-controlled pull-off (He, Li & Popov 2020).
"""

from .params import BrushParams, ParameterError, SolverOptions
from .curve import simulate

__all__ = ["BrushParams", "ParameterError", "SolverOptions", "simulate"]
