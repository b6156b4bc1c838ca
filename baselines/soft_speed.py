"""``soft_speed``: a PI speed loop tuned to damp the string's lowest torsional mode.

NOV's SoftSpeed (Kyllingstad & Nessjoen 2009, SPE/IADC 119660; the SoftTorque idea goes back
to Kyllingstad & Halsey 1988) keeps the rig's ordinary PI speed controller but tunes it so
that, at the stick-slip frequency, the top drive behaves as a pure damper matched to the drill
pipe and absorbs the torsional waves coming up the string instead of reflecting them. The
mechanical impedance a PI-controlled drive of inertia ``J`` presents to the string is
(:func:`baselines.string_modes.top_drive_impedance`)::

    Z_td(w) = kp + c_dt + i (w J_dt - ki / w)

Tuning from the controller's model of the string:

* ``ki = w_s^2 J_dt`` cancels the drive's inertia at the stick-slip frequency ``w_s`` (the
  lowest clamped-top, stuck-bit mode, :func:`baselines.string_modes.stick_slip_frequency`), so
  ``Z_td(w_s)`` is real;
* ``kp = impedance_factor * Z - c_dt``: the drive's whole resistance at ``w_s`` (controller
  plus the drive's own damping ``c_dt``) equals ``impedance_factor`` times the pipe impedance
  ``Z = sqrt(k_pi J_pi)``; with the default factor 1 the reflection coefficient at ``w_s`` is 0.
  When the drive's own damping already exceeds that target (a soft pipe: ``c_dt >
  impedance_factor Z``) no ``kp`` can lower the resistance, and ``kp = 0`` is the closest match
  (reflection ``(Z - c_dt) / (Z + c_dt)``);
* inertia compensation: the set-point acceleration is fed forward, ``J_dt d(ref)/dt``, so that
  the drive follows set-point changes without loading the (soft) PI loop.

So ``u = kp (ref - x1) + ki integral(ref - x1) + J_dt d(ref)/dt``. For ``zribi2024``:
``w_s = 0.6258 rad/s`` (period 10.0 s), ``Z = 1,393.6 N m s/rad``, ``kp = 968.6 N m s/rad``,
``ki = 364.2 N m/rad``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from baselines.base import Gains
from baselines.speed_loop import DriveLimits, SpeedLoopController, SpeedLoopTuning
from baselines.string_modes import string_view
from drill_env.distributed import DistributedStringParameters
from drill_env.parameters import DrillStringParameters
from drill_env.validation import shown

__all__ = ["SoftSpeed", "SoftSpeedGains"]


@dataclass(frozen=True)
class SoftSpeedGains(Gains):
    """Tuning knobs of the soft speed loop.

    Attributes:
        impedance_factor: The drive's resistance at the stick-slip frequency as a multiple of
            the pipe impedance, dimensionless (in (0, 100]; below ``c_dt / Z`` the loop has
            ``kp = 0``).
        frequency_factor: Tuning frequency as a multiple of the stick-slip frequency,
            dimensionless (in (0, 100]).
        inertia_compensation: Feed the set-point acceleration forward through ``J_dt``.
        limits: Drive torque limits for anti-windup.
    """

    impedance_factor: float = 1.0
    frequency_factor: float = 1.0
    inertia_compensation: bool = True
    limits: DriveLimits = field(default_factory=DriveLimits)

    def __post_init__(self) -> None:
        self._check_finite()
        self._check("impedance_factor", "(0, 100]", 0 < self.impedance_factor <= 100)
        self._check("frequency_factor", "(0, 100]", 0 < self.frequency_factor <= 100)
        if not isinstance(self.inertia_compensation, bool):
            raise TypeError(
                "SoftSpeedGains.inertia_compensation must be True or False, got "
                f"{shown(self.inertia_compensation)}"
            )
        if not isinstance(self.limits, DriveLimits):
            raise TypeError(
                f"SoftSpeedGains.limits must be a DriveLimits, got {shown(self.limits)}"
            )


class SoftSpeed(SpeedLoopController):
    """PI speed loop tuned as a matched damper at the stick-slip frequency (SoftSpeed)."""

    name = "soft_speed"
    rig_loop = True
    gains_type = SoftSpeedGains

    def tuning(
        self, model: DrillStringParameters | DistributedStringParameters | None = None
    ) -> SpeedLoopTuning:
        """``kp = max(impedance_factor Z - c_dt, 0)``, ``ki = (frequency_factor w_s)^2 J_dt``,
        ``j_ff = J_dt`` (when compensating)."""
        model = self.model if model is None else model
        m = string_view(model)
        g: SoftSpeedGains = self.gains_for(model)
        z = m.impedance
        w_s = m.stick_slip_rad_s
        kp = max(g.impedance_factor * z - m.c_dt, 0.0)
        ki = (g.frequency_factor * w_s) ** 2 * m.J_dt
        return SpeedLoopTuning(
            kp=kp,
            ki=ki,
            j_ff=m.J_dt if g.inertia_compensation else 0.0,
            pipe_impedance=z,
            stick_slip_rad_s=w_s,
        )
