"""Physical parameters of the 4-DOF torsional drill string (docs/specification.md section 1).

Every field is in SI units. Parameter sets are frozen dataclasses validated on creation;
variants are made with :func:`dataclasses.replace`, which validates again.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from drill_env.layout import N_PLANT_PARAMS
from drill_env.validation import check_finite_fields, require, shown

__all__ = [
    "PLANT_DT_S",
    "PRESETS",
    "DrillStringParameters",
    "plant_parameter_vector",
    "resolve_parameters",
    "scale_uncertain",
]

PLANT_DT_S: Final = 1e-3
"""Plant integration step and zero-order-hold period of the top-drive torque, s."""


@dataclass(frozen=True)
class DrillStringParameters:
    """Inertias, couplings and bit-rock friction of the lumped drill string.

    Attributes:
        J_dt: Top-drive (rotary table) inertia, kg m^2.
        J_pi: Drill-pipe inertia, kg m^2.
        J_co: Drill-collar (BHA) inertia, kg m^2.
        J_bi: Bit inertia, kg m^2.
        c_dt: Top-drive viscous damping to ground, N m s/rad.
        c_pi: Damping between top drive and pipes, N m s/rad.
        c_co: Damping between pipes and collars, N m s/rad.
        c_bi: Damping between collars and bit, N m s/rad.
        c_bit: Bit viscous damping to ground, N m s/rad.
        k_pi: Drill-pipe torsional stiffness, N m/rad.
        k_co: Collar torsional stiffness, N m/rad.
        k_bi: Collar-to-bit torsional stiffness, N m/rad.
        R: Bit radius, m.
        mu_a: Static (maximum) bit-rock friction coefficient, dimensionless.
        mu_0: Sliding (Coulomb) friction coefficient, dimensionless.
        xi: Decline rate of the Stribeck term, s/rad.
        Dw: Half-width of the stick band of the Karnopp model, rad/s.
    """

    J_dt: float = 930.0
    J_pi: float = 2782.25
    J_co: float = 750.0
    J_bi: float = 471.96
    c_dt: float = 425.0
    c_pi: float = 193.61
    c_co: float = 190.0
    c_bi: float = 181.49
    c_bit: float = 50.0
    k_pi: float = 698.06
    k_co: float = 1080.0
    k_bi: float = 907.48
    R: float = 0.15
    mu_a: float = 0.8
    mu_0: float = 0.5
    xi: float = 0.5
    Dw: float = 1e-3

    def __post_init__(self) -> None:
        check_finite_fields(self)
        for name in ("J_dt", "J_pi", "J_co", "J_bi", "k_pi", "k_co", "k_bi", "R", "Dw"):
            require(name, getattr(self, name), "> 0", getattr(self, name) > 0)
        for name in ("c_dt", "c_pi", "c_co", "c_bi", "c_bit", "xi"):
            require(name, getattr(self, name), ">= 0", getattr(self, name) >= 0)
        require("mu_0", self.mu_0, f"0 < mu_0 <= mu_a = {self.mu_a}", 0 < self.mu_0 <= self.mu_a)

    def static_torque_nm(self, wob_n: float) -> float:
        """Maximum static bit torque ``T_a = mu_a * WOB * R``, N m."""
        return self.mu_a * wob_n * self.R

    def sliding_torque_nm(self, wob_n: float) -> float:
        """Sliding bit torque ``T_0 = mu_0 * WOB * R``, N m."""
        return self.mu_0 * wob_n * self.R

    def steady_torque_nm(self, bit_speed_rad_s: float, wob_n: float) -> float:
        """Top-drive torque that holds the whole string at one constant speed, N m.

        At steady rotation every twist is constant and all inertias share the speed ``V``, so
        ``u = (c_dt + c_bit) V + T_0 + (T_a - T_0) exp(-xi V)`` (docs/specification.md section 2), for ``V > 0``.
        """
        t_a = self.static_torque_nm(wob_n)
        t_0 = self.sliding_torque_nm(wob_n)
        v = bit_speed_rad_s
        return (self.c_dt + self.c_bit) * v + t_0 + (t_a - t_0) * math.exp(-self.xi * abs(v))


PRESETS: Final[dict[str, DrillStringParameters]] = {
    # Table 2 of Zribi, Sidhom & Gharib (2024) as corrected by docs/specification.md section 1.
    "zribi2024": DrillStringParameters(),
    # The original 4-DOF set of Navarro-Lopez & Cortes (2007).
    "navarro_lopez2007": DrillStringParameters(
        J_bi=471.9698,
        c_pi=139.6126,
        k_pi=698.063,
        R=0.155575,
        xi=0.9,
        Dw=1e-6,
    ),
}


def resolve_parameters(value: str | DrillStringParameters) -> DrillStringParameters:
    """Return the parameter set named by ``value`` (a preset name) or ``value`` itself."""
    if isinstance(value, DrillStringParameters):
        return value
    if isinstance(value, str):
        try:
            return PRESETS[value]
        except KeyError:
            raise ValueError(
                f"parameters = {shown(value)} is not a known preset: allowed {sorted(PRESETS)}"
            ) from None
    raise TypeError(
        f"parameters must be a preset name or a DrillStringParameters, got {type(value).__name__}"
    )


def scale_uncertain(
    params: DrillStringParameters, deltas: tuple[float, float, float]
) -> DrillStringParameters:
    """Apply the paper's Table 3 uncertainty: ``c_pi (1+D1)``, ``k_pi (1+D2)``, ``c_dt (1+D3)``."""
    d1, d2, d3 = deltas
    return dataclasses.replace(
        params,
        c_pi=params.c_pi * (1 + d1),
        k_pi=params.k_pi * (1 + d2),
        c_dt=params.c_dt * (1 + d3),
    )


def plant_parameter_vector(params: DrillStringParameters) -> npt.NDArray[np.float64]:
    """Pack ``params`` into the float64 vector the kernels read (``drill_env.layout.P_*``): the
    17 fields in order, then the reciprocals of the four inertias (1/(kg m^2)), so that the hot
    loop multiplies."""
    fields = [float(getattr(params, f.name)) for f in dataclasses.fields(params)]
    inverse = [1.0 / params.J_dt, 1.0 / params.J_pi, 1.0 / params.J_co, 1.0 / params.J_bi]
    vector = np.array(fields + inverse, dtype=np.float64)
    assert vector.shape == (N_PLANT_PARAMS,)
    return vector
