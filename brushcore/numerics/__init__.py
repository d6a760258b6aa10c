"""The engine: half-space kernel, DC-FFT convolution, the brush operator, preconditioners,
CG, the event-driven pull-off and protocol engines, solver options and threads.

Knows nothing of layouts, files or the workflow.
"""
