"""The quasi-static engines: the exact event-driven pull-off and the protocol
engine (heights, stiffnesses, preload, loading-unloading cycles).

Uses the linear solvers and `numerics.options`.
"""
