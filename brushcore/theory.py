"""Analytic reference solutions and the paper's normalisations (pure functions).

Every formula the tests and the figures compare against lives here, so the
solver, the tests and the plots cannot drift apart.  Units are whatever the
caller uses consistently (the package default is E* = dgamma = h = 1).

References
----------
He, Li & Popov, Lubricants 8 (2020) 94 ("the paper"), eqs. 5, 6, 20-27.
Kendall, J. Phys. D 4 (1971) 1186.
Pohrt & Popov, Facta Univ. Mech. Eng. 13 (2015) 3-10.
"""

from __future__ import annotations

import math

import numpy as np

#: Griffith energy balance over one square element of side h under a flat
#: punch's edge singularity (Pohrt & Popov 2015, eq. 14):
#: beta = [4 ln(1 + sqrt 2) - (4/3)(sqrt 2 - 1)] / (2 pi).
BETA = (4.0 * math.log(1.0 + math.sqrt(2.0)) - 4.0 / 3.0 * (math.sqrt(2.0) - 1.0)) / (
    2.0 * math.pi
)


def critical_stress(e_star: float, dgamma: float, h: float) -> float:
    """Mesh-dependent detachment stress sigma_c = sqrt(E* dgamma / (beta h)).

    Parameters
    ----------
    e_star : effective modulus E* [stress]
    dgamma : work of adhesion [energy / area]
    h : element size [length]

    Returns
    -------
    float
        Critical tensile stress [stress] (Pohrt & Popov 2015).
    """
    return math.sqrt(e_star * dgamma / (BETA * h))


def self_compliance(e_star: float, h: float) -> float:
    """Centre displacement of an h x h square under unit pressure, 4 ln(1+sqrt2) h / (pi E*)."""
    return 4.0 * math.log(1.0 + math.sqrt(2.0)) * h / (math.pi * e_star)


def flat_punch_stiffness(radius: float, e_star: float) -> float:
    """Normal stiffness 2 a E* of a rigid circular flat punch [force / length]."""
    return 2.0 * radius * e_star


def kendall_force(radius: float, e_star: float, dgamma: float) -> float:
    """Kendall's pull-off force sqrt(8 pi E* dgamma a^3) of a flat punch [force]."""
    return math.sqrt(8.0 * math.pi * e_star * dgamma * radius**3)


def equivalent_radius(area: float) -> float:
    """Radius a0 = sqrt(A / pi) of the compact punch with the same area [length]."""
    return math.sqrt(area / math.pi)


def force_scale(area: float, e_star: float, dgamma: float) -> float:
    """Kendall force of the compact punch of area A, the paper's eq. 20 scale."""
    return kendall_force(equivalent_radius(area), e_star, dgamma)


def displacement_scale(area: float, e_star: float, dgamma: float) -> float:
    """Kendall's critical displacement sqrt(2 pi dgamma a0 / E*), eq. 21 [length]."""
    return math.sqrt(2.0 * math.pi * dgamma * equivalent_radius(area) / e_star)


def work_scale(area: float, dgamma: float) -> float:
    """Work of separation 2 pi a0^2 dgamma of the compact punch, eq. 23 [energy]."""
    return 2.0 * math.pi * equivalent_radius(area) ** 2 * dgamma


def stiffness_from_kbar(kbar: float, e_star: float, side: float) -> float:
    """Pillar spring stiffness k = kbar E* L (eq. 22) [force / length]."""
    return kbar * e_star * side


def rigid_limit(phi: float) -> float:
    """Normalised adhesive force of a rigid flat brush, phi^(-1/4) (eq. 5)."""
    return phi**-0.25


def soft_limit(n_pillars: int | np.ndarray) -> float | np.ndarray:
    """Normalised adhesive force of independent soft pillars, N^(1/4) (eq. 6)."""
    return np.asarray(n_pillars, dtype=float) ** 0.25


def soft_work(n_pillars: int | np.ndarray, phi: float, kbar: float | np.ndarray):
    """Normalised work of separation stored in soft springs, eqs. 25-27.

    Each of the N springs carries f = N^(-3/4) F_K at pull-off and stores
    f^2 / (2k); normalising by 2 pi a0^2 dgamma with a0 = L sqrt(phi / pi)
    and k = kbar E* L gives W_S = 2 sqrt(phi / pi) / (sqrt(N) kbar).
    """
    n = np.asarray(n_pillars, dtype=float)
    return 2.0 * math.sqrt(phi / math.pi) / (np.sqrt(n) * np.asarray(kbar, dtype=float))


def spring_punch_work(pull_off: float, spring: float, contact: float) -> float:
    """Work to separate one punch on a spring that detaches at once [energy].

    Under displacement control the punch and its spring are in series, so
    the force rises linearly with compliance 1/k + 1/k_c up to the pull-off
    force and then drops to zero: W = f^2 (1/k + 1/k_c) / 2.
    """
    return 0.5 * pull_off**2 * (1.0 / spring + 1.0 / contact)
