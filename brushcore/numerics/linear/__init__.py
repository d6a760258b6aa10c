"""One contact state: the brush operator (half space plus pillar springs), CG and
its preconditioners (per-pillar block inverses, tiles, single-pillar solves).

Uses the half space and the platform; knows nothing of events.
"""
