"""Adaptive sliding mode (paper eq. 47-48): ``u_disc = -k4 sign(s)`` with
``k4' = mu11 |s| sign(|s| - delta)`` while ``k4 > mu22``, else ``k4' = mu22``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.base import check_gain
from baselines.smc import SlidingModeController, SurfaceGains
from drill_env.control_laws import LAW_ASMC

__all__ = ["ASMC", "ASMCGains"]


@dataclass(frozen=True)
class ASMCGains(SurfaceGains):
    """Gains of the ASMC (Table 1; ``k0`` from SPEC section 3).

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
        check_gain(self, "mu11", "> 0", self.mu11 > 0)
        check_gain(self, "mu22", "> 0", self.mu22 > 0)
        check_gain(self, "k0", "> 0", self.k0 > 0)

    def law_gains(self) -> tuple[float, ...]:
        return (self.mu11, self.mu22)

    def initial_gain(self) -> float:
        return self.k0


class ASMC(SlidingModeController):
    """Adaptive sliding-mode controller."""

    name = "asmc"
    law_id = LAW_ASMC
    gains_type = ASMCGains
