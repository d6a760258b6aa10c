"""The physical problem: parameters, layouts and pillar shapes, rough and graded inputs,
the theory of the limits, one simulated curve as an xarray Dataset, provenance.

Uses the numerics; knows nothing of files of many curves or the workflow.
"""
