"""A protocol's legs and its result: waypoints, the raw curve of a run, and
the work integrals over it (`protocol.run_protocol` runs the legs).

Directions of travel along d: APPROACH (-1, towards the substrate), START
(0, first touch) and RETRACT (+1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brushcore.validation import is_one_of, is_real, normalise, require, suggest_keywords

APPROACH, START, RETRACT = -1, 0, 1
KINDS = ("force", "displacement", "separation")


@suggest_keywords
@dataclass(frozen=True)
class Waypoint:
    """One leg of a protocol: move d until the target is reached.

    Parameters
    ----------
    kind : "force" (reach the total force ``value``, tensile positive, so
        a preload P is ``Waypoint("force", -P)``), "displacement" (reach
        d = ``value``) or "separation" (retract until no element is
        attached; takes no ``value``: one other than 0 is refused).
    value : the target, in the units of whoever reads it: normalised in
        `brushcore.simulate(..., protocol=...)` (forces in F_K,
        displacements in d_K, as the curve's ``*_normalized`` variables),
        dimensional [force or length] in this module's engine
        (`run_protocol`, `preload_protocol`); required for "force" and
        "displacement"

    The direction follows from the state: towards the target.  A force
    target that cannot be reached (the brush lets go first on retraction)
    ends the leg at complete separation.
    """

    kind: str
    value: float | None = None  # 0.0 for separation once made

    def __post_init__(self) -> None:
        normalise(self, (), (), ("kind",))  # a 0-d text array, np.str_: str
        require(is_one_of(self.kind, KINDS), "waypoint kind", self.kind, f"one of {KINDS}")
        if self.value is None:  # a target left out is no target of 0
            require(self.kind == "separation", "waypoint value", None,
                    f"a finite number: a {self.kind} waypoint needs its target")
            object.__setattr__(self, "value", 0.0)
        normalise(self, (), ("value",))  # np.float32 and 0-d arrays become floats
        require(is_real(self.value) and np.isfinite(self.value), "waypoint value", self.value,
                "a finite number")
        require(self.kind != "separation" or self.value == 0.0, "waypoint value", self.value,
                "none for a separation waypoint (it retracts until every element lets go)")


def preload_protocol(preload: float) -> tuple[Waypoint, ...]:
    """Approach until the compressive force is ``preload`` [force], then retract
    until everything has let go."""
    if not preload >= 0.0:
        raise ValueError(f"preload={preload!r} is invalid: allowed a number >= 0")
    return (Waypoint("force", -float(preload)), Waypoint("separation"))


@dataclass(frozen=True)
class ProtocolCurve:
    """Raw result of one protocol run (units of the inputs).

    Attributes
    ----------
    displacement, force : d [length] and F [force, tensile positive] per step
    attached_elements, attached_pillars : contact per step
    branch : index of the waypoint being followed per step (-1 at first touch)
    direction : -1 approach, +1 retraction, 0 first touch, per step
    waypoint_step : the step at which each waypoint was reached
    attach_step, detach_step : per pillar element (operator order), the last
        step at which it attached (-1: never) and the first step without it
        after its last detachment (-1: never detached)
    pillar_force_at_peak : per pillar, force [force] at the largest tensile
        force of the last retraction branch (load sharing at F_ad)
    peak_step : the step of that force
    let_go : per pillar, d [length] at which its last element detached (NaN:
        still attached or never touched)
    attached_at_waypoint : per waypoint, attached elements (operator order)
    attached_at_peak : attached elements at ``peak_step``
    pulls : (P, 2) int, the first and last step of every retraction branch in
        order: the retraction waypoints that follow one another from a turn
        out of an approach (included) to the next turn back into one
        (included) or the end; F_ad and W are taken over the last
    events, cg_iterations : counts over the run
    """

    displacement: np.ndarray
    force: np.ndarray
    attached_elements: np.ndarray
    attached_pillars: np.ndarray
    branch: np.ndarray
    direction: np.ndarray
    waypoint_step: np.ndarray
    attach_step: np.ndarray
    detach_step: np.ndarray
    pillar_force_at_peak: np.ndarray
    peak_step: int
    let_go: np.ndarray
    attached_at_waypoint: tuple[np.ndarray, ...]
    attached_at_peak: np.ndarray
    events: int
    cg_iterations: int
    pulls: np.ndarray

    @property
    def retraction(self) -> np.ndarray:
        """Per step, whether it belongs to the last retraction branch (bool)."""
        on = np.zeros(self.displacement.size, dtype=bool)
        if len(self.pulls):
            first, last = self.pulls[-1]
            on[first:last + 1] = True
        return on


def positive_work(displacement: np.ndarray, force: np.ndarray) -> float:
    """Exact integral of max(F, 0) dd over a piecewise linear curve [energy].

    Segments that cross zero are split at the crossing; vertical drops (at
    fixed d) contribute nothing.

    Parameters
    ----------
    displacement : (S,) the curve's displacements d, in order [length]
    force : (S,) the force F at each [force]

    Returns
    -------
    float
        The work [force x length]: a curve in F_K and d_K gives it in
        F_K d_K.
    """
    displacement, force = np.asarray(displacement), np.asarray(force)
    if displacement.ndim != 1 or displacement.shape != force.shape:
        raise ValueError(f"displacement and force must be 1-D of one length: shapes "
                         f"{displacement.shape} and {force.shape}")
    d0, d1 = displacement[:-1], displacement[1:]
    f0, f1 = force[:-1], force[1:]
    dd = d1 - d0
    both = (f0 >= 0) & (f1 >= 0)
    work = np.where(both, 0.5 * (f0 + f1) * dd, 0.0)
    cross = (f0 > 0) != (f1 > 0)
    cross &= ~both
    with np.errstate(invalid="ignore", divide="ignore"):
        pos = np.maximum(f0, f1)
        frac = np.where(cross, pos / np.abs(f1 - f0), 0.0)
    work += np.where(cross, 0.5 * pos * frac * dd, 0.0)
    return float(work.sum())


def loop_energy(displacement: np.ndarray, force: np.ndarray) -> float:
    """Work done on the brush along the path, the integral of F dd [energy].

    Over a protocol from first touch (no contact, no stress) to complete
    separation it is the energy dissipated, >= 0; over a closed cycle in
    which the contact does not change it is zero.
    """
    return float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(displacement)))
