"""Modified sliding mode with an exponent reaching law (paper eq. 46):
``u_disc = -k2 |s|^(1/2) sign(s) - k3 s``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.base import check_gain
from baselines.smc import SlidingModeController, SurfaceGains
from drill_env.control_laws import LAW_MSMC

__all__ = ["MSMC", "MSMCGains"]


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
        check_gain(self, "k2", "> 0", self.k2 > 0)
        check_gain(self, "k3", ">= 0", self.k3 >= 0)

    def law_gains(self) -> tuple[float, ...]:
        return (self.k2, self.k3)


class MSMC(SlidingModeController):
    """Modified sliding-mode controller."""

    name = "msmc"
    law_id = LAW_MSMC
    gains_type = MSMCGains
