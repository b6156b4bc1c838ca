"""``stiff_pi``: a conventional stiff top-drive speed loop (the reference industry case).

A top drive in plain speed control holds its speed close to the set-point whatever the string
does: seen from the string it is an almost rigid, clamped end that reflects every torsional
wave back down (reflection coefficient near -1), which is what lets stick-slip build up at low
speed and high WOB (Kyllingstad & Halsey 1988; Dwars 2015). The loop here is a PI on the
measured top-drive speed with the set-point ``ref`` (the reference bit speed)::

    u = kp (ref - x1) + ki integral(ref - x1)

Tuning from the controller's model of the string:

* ``kp = bandwidth_factor * Z`` with ``Z = sqrt(k_pi J_pi)`` the pipe impedance
  (:func:`baselines.string_modes.pipe_impedance`); the default factor 50 makes the drive's
  resistance 50 times the pipe impedance, so ``|r| = (50 - 1) / (50 + 1) = 0.96``: a stiff rig
  drive. For ``zribi2024``: ``kp = 69,681 N m s/rad``.
* ``ki = kp^2 / (4 zeta^2 J_dt)``: the PI loop around the top-drive inertia alone,
  ``J_dt s^2 + kp s + ki``, has damping ratio ``zeta`` (``damping_ratio``, default 1, critical).
  For ``zribi2024``: ``ki = 1.305e6 N m/rad``, closed-loop corner ``kp / (2 J_dt) = 37 rad/s``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from baselines.base import Gains
from baselines.speed_loop import DriveLimits, SpeedLoopController, SpeedLoopTuning
from baselines.string_modes import string_view
from drill_env.distributed import DistributedStringParameters
from drill_env.parameters import DrillStringParameters
from drill_env.validation import shown

__all__ = ["StiffPI", "StiffPIGains"]


@dataclass(frozen=True)
class StiffPIGains(Gains):
    """Tuning knobs of the stiff speed loop.

    Attributes:
        bandwidth_factor: ``kp`` as a multiple of the pipe impedance ``Z``, dimensionless
            (in (0, 10,000]).
        damping_ratio: Damping ratio of the PI loop around the top-drive inertia, sets ``ki``
            (in (0, 100]).
        limits: Drive torque limits for anti-windup.
    """

    bandwidth_factor: float = 50.0
    damping_ratio: float = 1.0
    limits: DriveLimits = field(default_factory=DriveLimits)

    def __post_init__(self) -> None:
        self._check_finite()
        self._check("bandwidth_factor", "(0, 10000]", 0 < self.bandwidth_factor <= 10_000)
        self._check("damping_ratio", "(0, 100]", 0 < self.damping_ratio <= 100)
        if not isinstance(self.limits, DriveLimits):
            raise TypeError(f"StiffPIGains.limits must be a DriveLimits, got {shown(self.limits)}")


class StiffPI(SpeedLoopController):
    """Stiff top-drive speed PI loop."""

    name = "stiff_pi"
    gains_type = StiffPIGains

    def tuning(
        self, model: DrillStringParameters | DistributedStringParameters | None = None
    ) -> SpeedLoopTuning:
        """``kp = bandwidth_factor Z``, ``ki = kp^2 / (4 damping_ratio^2 J_dt)``."""
        model = self.model if model is None else model
        m = string_view(model)
        g: StiffPIGains = self.gains_for(model)
        z = m.impedance
        kp = g.bandwidth_factor * z
        ki = kp**2 / (4.0 * g.damping_ratio**2 * m.J_dt)
        return SpeedLoopTuning(kp=kp, ki=ki, pipe_impedance=z, stick_slip_rad_s=m.stick_slip_rad_s)
