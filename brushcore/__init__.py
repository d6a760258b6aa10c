"""brushcore: adhesive pull-off of spring-mounted fibrillar brushes.

Boundary elements on a non-periodic elastic half space (pruned DC-FFT),
pillar springs coupled into the influence operator, preconditioned CG, the
mesh-dependent JKR detachment criterion of Pohrt & Popov (2015), and an
event-driven displacement-controlled pull-off (He, Li & Popov 2020).

The package is layered; imports point down only:

- ``brushcore.numerics``: the engine, itself layered: ``platform`` (arrays, threads,
  FFT libraries), ``halfspace`` (kernel, DC-FFT convolution), ``linear`` (operator,
  preconditioners, CG), ``events`` (event-driven pull-off and protocols), and options;
- ``brushcore.model``: the physical problem (parameters, layouts and shapes,
  rough and graded inputs, theory, one curve as a Dataset, provenance);
- ``brushcore.data``: files and analysis (curve files, the aggregated sweep,
  convergence studies, summary tables, figures, job logs);
- ``brushcore.cli`` on top, and ``brushcore.validation`` (the error type) below all.
"""

from brushcore.data.io import read_curve, write_curve
from brushcore.model import theory
from brushcore.model.curve import FirstTouchWarning, simulate
from brushcore.model.inputs import with_input_files
from brushcore.model.layout import generated_table
from brushcore.model.layout_file import file_params
from brushcore.model.params import BrushParams
from brushcore.model.pillar_table import read_pillar_table, save_pillar_table
from brushcore.model.scales import unit_scales
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.events.waypoints import Waypoint, positive_work
from brushcore.validation import ParameterError
from brushcore.model.provenance import version as _version

#: The installed version (``brushcore --version`` adds the commit).
__version__ = _version()

__all__ = ["BrushParams", "FirstTouchWarning", "ParameterError", "SolverOptions", "Waypoint",
           "file_params", "generated_table", "positive_work", "read_curve",
           "read_pillar_table", "save_pillar_table", "simulate", "theory", "unit_scales",
           "with_input_files", "write_curve"]
