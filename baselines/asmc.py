"""Adaptive sliding mode (paper eq. 47-48): ``u_disc = -k4 sign(s)`` with
``k4' = mu11 |s| sign(|s| - delta)`` while ``k4 > mu22``, else ``k4' = mu22``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.smc import VARIANT_ASMC, SlidingModeController, SurfaceGains, smc_law
from drill_env.control import compiled_law_function

__all__ = ["asmc_law", "ASMC", "ASMCGains"]


@dataclass(frozen=True)
class ASMCGains(SurfaceGains):
    """Gains of the ASMC (Table 1; ``k0`` from docs/specification.md section 3).

    Attributes:
        mu11: Adaptation rate, N m s^-1 (rad/s)^-1 (> 0).
        mu22: Floor of the gain and its growth rate below the floor (> 0).
        k0: Adaptive gain at t = 0, N m (> 0).
    """

    mu11: float = 0.1
    mu22: float = 0.01
    k0: float = 0.2

    def __post_init__(self) -> None:
        super().__post_init__()
        self._check("mu11", "> 0", self.mu11 > 0)
        self._check("mu22", "> 0", self.mu22 > 0)
        self._check("k0", "> 0", self.k0 > 0)

    def law_gains(self) -> tuple[float, ...]:
        return (self.mu11, self.mu22)

    def initial_gain(self) -> float:
        return self.k0


@compiled_law_function
def asmc_law(lp, ls, m, ref, dt):
    """The compiled law of ``asmc`` (see :func:`baselines.smc.smc_torque`)."""
    return smc_law(VARIANT_ASMC, lp, ls, m, ref, dt)


class ASMC(SlidingModeController):
    """Adaptive sliding-mode controller."""

    name = "asmc"
    variant = VARIANT_ASMC
    law = asmc_law
    gains_type = ASMCGains
