"""State derivative of the 4-DOF torsional drill string (docs/specification.md section 1, paper eq. 28).

State ``x = (w_dt, phi_dt - phi_pi, w_pi, phi_pi - phi_co, w_co, phi_co - phi_bi, w_bi)``:
speeds in rad/s, twists in rad. The plant parameter vector ``p`` is the one packed by
:func:`drill_env.parameters.plant_parameter_vector`. States travel as 7-tuples of floats so
that the compiled integrator keeps them in registers.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.friction import STUCK, slip_torque, string_torque_on_bit
from drill_env.layout import (
    P_C_BI,
    P_C_BIT,
    P_C_CO,
    P_C_DT,
    P_C_PI,
    P_INV_J_BI,
    P_INV_J_CO,
    P_INV_J_DT,
    P_INV_J_PI,
    P_K_BI,
    P_K_CO,
    P_K_PI,
    P_XI,
)
from drill_env.parameters import DrillStringParameters, plant_parameter_vector

__all__ = ["derivative", "state_derivative"]


@njit(cache=True)
def derivative(x, u: float, p, t_a: float, t_0: float, mode: int):
    """Time derivative of the state tuple ``x`` under top-drive torque ``u`` (N m).

    Args:
        x: State 7-tuple (rad/s and rad).
        u: Top-drive torque, N m.
        p: Plant parameter vector (:func:`drill_env.parameters.plant_parameter_vector`).
        t_a: Maximum static bit torque, N m.
        t_0: Sliding bit torque, N m.
        mode: Bit slip mode: 0 stuck (bit speed held at 0), +1/-1 slipping.

    Returns:
        The 7-tuple ``dx/dt``.
    """
    x1, x2, x3, x4, x5, x6, x7 = x
    inv_dt, inv_pi, inv_co, inv_bi = p[P_INV_J_DT], p[P_INV_J_PI], p[P_INV_J_CO], p[P_INV_J_BI]
    c_dt, c_pi, c_co, c_bi, c_bit = p[P_C_DT], p[P_C_PI], p[P_C_CO], p[P_C_BI], p[P_C_BIT]
    k_pi, k_co, k_bi = p[P_K_PI], p[P_K_CO], p[P_K_BI]
    d1 = (-(c_dt + c_pi) * x1 - k_pi * x2 + c_pi * x3 + u) * inv_dt
    d3 = (c_pi * x1 + k_pi * x2 - (c_pi + c_co) * x3 - k_co * x4 + c_co * x5) * inv_pi
    d5 = (c_co * x3 + k_co * x4 - (c_co + c_bi) * x5 - k_bi * x6 + c_bi * x7) * inv_co
    if mode == STUCK:
        d7 = 0.0
    else:
        t_e = string_torque_on_bit(x5, x6, x7, c_bi, k_bi, c_bit)
        d7 = (t_e - slip_torque(x7, mode, t_a, t_0, p[P_XI])) * inv_bi
    return (d1, x1 - x3, d3, x3 - x5, d5, x5 - x7, d7)


def state_derivative(
    x: npt.ArrayLike,
    torque_nm: float,
    params: DrillStringParameters,
    wob_n: float,
    bit_stuck: bool,
) -> npt.NDArray[np.float64]:
    """Convenience wrapper of :func:`derivative` for numpy users.

    Args:
        x: State, shape (7,), rad/s and rad.
        torque_nm: Top-drive torque, N m.
        params: Plant parameters.
        wob_n: Weight on bit, N.
        bit_stuck: Whether the bit is held by static friction (its speed must then be 0).

    Returns:
        ``dx/dt``, shape (7,).
    """
    state = np.asarray(x, dtype=np.float64)
    if state.shape != (7,):
        raise ValueError(f"x must have shape (7,), got {state.shape}")
    mode = STUCK if bit_stuck else (1 if state[6] >= 0 else -1)
    dx = derivative(
        tuple(float(v) for v in state),
        float(torque_nm),
        plant_parameter_vector(params),
        params.static_torque_nm(wob_n),
        params.sliding_torque_nm(wob_n),
        mode,
    )
    return np.array(dx, dtype=np.float64)
