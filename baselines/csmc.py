"""Classic first-order sliding mode (paper eq. 45): ``u_disc = -k1 sign(s)``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.smc import VARIANT_CSMC, SlidingModeController, SurfaceGains, smc_law
from drill_env.control import compiled_law_function

__all__ = ["csmc_law", "CSMC", "CSMCGains"]


@dataclass(frozen=True)
class CSMCGains(SurfaceGains):
    """Gains of the CSMC (Table 1).

    Attributes:
        k1: Switching gain, N m (> 0).
    """

    k1: float = 3.0

    def __post_init__(self) -> None:
        super().__post_init__()
        self._check("k1", "> 0", self.k1 > 0)

    def law_gains(self) -> tuple[float, ...]:
        return (self.k1,)


@compiled_law_function
def csmc_law(lp, ls, m, ref, dt):
    """The compiled law of ``csmc`` (see :func:`baselines.smc.smc_torque`)."""
    return smc_law(VARIANT_CSMC, lp, ls, m, ref, dt)


class CSMC(SlidingModeController):
    """Classic sliding-mode controller."""

    name = "csmc"
    variant = VARIANT_CSMC
    law = csmc_law
    gains_type = CSMCGains
