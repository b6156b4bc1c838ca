"""Modified sliding mode with an exponent reaching law (paper eq. 46):
``u_disc = -k2 |s|^(1/2) sign(s) - k3 s``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.smc import VARIANT_MSMC, SlidingModeController, SurfaceGains, smc_law
from drill_env.control import compiled_law_function

__all__ = ["msmc_law", "MSMC", "MSMCGains"]


@dataclass(frozen=True)
class MSMCGains(SurfaceGains):
    """Gains of the MSMC (Table 1).

    Attributes:
        k2: Gain of the square-root term, N m (rad/s)^-1/2 (> 0).
        k3: Linear gain, N m s/rad (>= 0).
    """

    k2: float = 3.0
    k3: float = 0.001

    def __post_init__(self) -> None:
        super().__post_init__()
        self._check("k2", "> 0", self.k2 > 0)
        self._check("k3", ">= 0", self.k3 >= 0)

    def law_gains(self) -> tuple[float, ...]:
        return (self.k2, self.k3)


@compiled_law_function
def msmc_law(lp, ls, m, ref, dt):
    """The compiled law of ``msmc`` (see :func:`baselines.smc.smc_torque`)."""
    return smc_law(VARIANT_MSMC, lp, ls, m, ref, dt)


class MSMC(SlidingModeController):
    """Modified sliding-mode controller."""

    name = "msmc"
    variant = VARIANT_MSMC
    law = msmc_law
    gains_type = MSMCGains
