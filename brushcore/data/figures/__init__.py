"""Figures from sweep datasets and curve files (matplotlib, no pyplot).

`paper`: the paper's Figures 5-8, the lattice comparison and the rigid
limit against phi; `rough`:
rough, graded and preloaded brushes and one protocol curve's loops and load
sharing; `convergence`: a mesh-refinement study; `common`: what they share.
Each figure function returns a `matplotlib.figure.Figure`; `save` writes
it.  The workflow's scripts name a figure by its function's name here.
"""

from brushcore.data.figures.common import save
from brushcore.data.figures.convergence import convergence
from brushcore.data.figures.paper import fig5, fig6, fig7, fig8, lattices, rigid_phi
from brushcore.data.figures.rough import (load_sharing, rough_loop, rough_preload,
                                          rough_roughness, rough_spread)

__all__ = ["convergence", "fig5", "fig6", "fig7", "fig8", "lattices", "load_sharing",
           "rigid_phi", "rough_loop", "rough_preload", "rough_roughness", "rough_spread",
           "save"]
