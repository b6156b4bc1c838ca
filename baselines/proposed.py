"""The paper's proposed adaptive sliding mode (eq. 11-13):
``u_disc = -k1 |s|^(1/2) sign(s) - a k1 s`` with
``k1' = mu1 |s|^b sign(|s| - delta)`` while ``k1 > alpha``, else ``k1' = mu2``."""

from __future__ import annotations

from dataclasses import dataclass

from baselines.smc import VARIANT_PROPOSED, SlidingModeController, SurfaceGains, smc_law
from drill_env.control import compiled_law_function

__all__ = ["proposed_law", "ProposedASMC", "ProposedGains"]


@dataclass(frozen=True)
class ProposedGains(SurfaceGains):
    """Gains of the proposed controller (Table 1; ``k0`` from docs/specification.md section 3).

    Attributes:
        mu1: Adaptation rate (> 0).
        mu2: Growth rate of the gain below ``alpha`` (> 0).
        alpha: Switching threshold of the gain (> 0, below ``k0``).
        a: Ratio of the linear gain to ``k1`` (>= 0, << 1).
        b: Exponent of ``|s|`` in the adaptation, in (0, 1].
        k0: Adaptive gain ``k1`` at t = 0 (> alpha).
    """

    mu1: float = 3.0
    mu2: float = 0.001
    alpha: float = 0.1
    a: float = 0.01
    b: float = 0.125
    k0: float = 0.2

    def __post_init__(self) -> None:
        super().__post_init__()
        self._check("mu1", "> 0", self.mu1 > 0)
        self._check("mu2", "> 0", self.mu2 > 0)
        self._check("alpha", "> 0", self.alpha > 0)
        self._check("a", ">= 0", self.a >= 0)
        self._check("b", "(0, 1]", 0 < self.b <= 1)
        self._check("k0", f"> alpha = {self.alpha}", self.k0 > self.alpha)

    def law_gains(self) -> tuple[float, ...]:
        return (self.mu1, self.mu2, self.alpha, self.a, self.b)

    def initial_gain(self) -> float:
        return self.k0


@compiled_law_function
def proposed_law(lp, ls, m, ref, dt):
    """The compiled law of ``proposed`` (see :func:`baselines.smc.smc_torque`)."""
    return smc_law(VARIANT_PROPOSED, lp, ls, m, ref, dt)


class ProposedASMC(SlidingModeController):
    """The paper's proposed adaptive sliding-mode controller."""

    name = "proposed"
    variant = VARIANT_PROPOSED
    law = proposed_law
    gains_type = ProposedGains
