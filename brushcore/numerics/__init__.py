"""The engine, in four layers, each using only those below it:

- ``platform``: array namespace (NumPy or CuPy), threads, MKL's FFTs, sparse sums;
- ``halfspace``: the half-space kernel, the DC-FFT convolution and its variants,
  far-field bounds and multipoles;
- ``linear``: the brush operator for one contact state, CG and its preconditioners;
- ``events``: the event-driven pull-off and the protocol engine;

and ``options``, the solver options every layer's caller validates at the edge.
Knows nothing of layouts, files or the workflow.
"""
