"""The quasi-static engines: the exact event-driven pull-off and the protocol
engine (heights, stiffnesses, preload, loading-unloading cycles), and a
protocol's waypoints and raw curve (`waypoints`).

Uses the linear solvers and `numerics.options`.
"""
