"""Classic first-order sliding mode (paper eq. 45): ``u_disc = -k1 sign(s)``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.base import check_gain
from baselines.smc import SlidingModeController, SurfaceGains
from drill_env.control_laws import LAW_CSMC

__all__ = ["CSMC", "CSMCGains"]


@dataclass(frozen=True)
class CSMCGains(SurfaceGains):
    """Gains of the CSMC (Table 1).

    Attributes:
        k1: Switching gain, N m (> 0).
    """

    k1: float = 3.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_gain(self, "k1", "> 0", self.k1 > 0)

    def law_gains(self) -> tuple[float, ...]:
        return (self.k1,)


class CSMC(SlidingModeController):
    """Classic sliding-mode controller."""

    name = "csmc"
    law_id = LAW_CSMC
    gains_type = CSMCGains
