"""Scaling of the observation vector of ``DrillString-v0``.

Layout (float32, every entry clipped to ``[-OBS_BOUND, OBS_BOUND]``):

=====  =========================================  ==========================
index  quantity                                   scale
=====  =========================================  ==========================
0      measured top-drive speed x1                ``SPEED_SCALE_RAD_S``
1      top-drive to pipe twist x2                 ``TWIST_SCALE_RAD``
2      measured pipe speed x3                     ``SPEED_SCALE_RAD_S``
3      pipe to collar twist x4                    ``TWIST_SCALE_RAD``
4      measured collar speed x5                   ``SPEED_SCALE_RAD_S``
5      collar to bit twist x6                     ``TWIST_SCALE_RAD``
6      measured bit speed x7                      ``SPEED_SCALE_RAD_S``
7      reference bit speed                        ``SPEED_SCALE_RAD_S``
8      last applied top-drive torque              ``torque_scale_nm``
9      base controller torque (residual mode)     ``torque_scale_nm``
10     base controller sliding variable (resid.)  ``SPEED_SCALE_RAD_S``
=====  =========================================  ==========================

``torque_scale_nm = max(|min_torque_nm|, |max_torque_nm|)``.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

__all__ = [
    "OBS_BOUND",
    "SPEED_SCALE_RAD_S",
    "TWIST_SCALE_RAD",
    "observation_size",
    "state_scales",
    "unscale_measurement",
]

SPEED_SCALE_RAD_S: Final = 20.0
"""Speeds (and the reference and sliding variable) are divided by this, rad/s."""
TWIST_SCALE_RAD: Final = 20.0
"""Twists are divided by this, rad."""
OBS_BOUND: Final = 50.0
"""Every scaled entry is clipped to [-OBS_BOUND, OBS_BOUND]."""

N_STATE_OBS: Final = 9
N_RESIDUAL_OBS: Final = 11


def state_scales() -> npt.NDArray[np.float64]:
    """Scale of each of the 7 state entries (rad/s for speeds, rad for twists)."""
    s, w = SPEED_SCALE_RAD_S, TWIST_SCALE_RAD
    return np.array([s, w, s, w, s, w, s])


def observation_size(residual: bool) -> int:
    """Length of the observation: 9, or 11 in residual mode."""
    return N_RESIDUAL_OBS if residual else N_STATE_OBS


def unscale_measurement(
    observation: npt.ArrayLike,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Recover the measured state (..., 7) and the reference speed (...,) from observations."""
    obs = np.asarray(observation, dtype=np.float64)
    return obs[..., :7] * state_scales(), obs[..., 7] * SPEED_SCALE_RAD_S
