"""``z_torque``: torsional impedance matching at the top drive (Shell's Z-Torque).

Z-Torque (Dwars 2015, SPE/IADC 173037 "Recent advances in soft torque rotary systems";
US 2016/0281488) keeps a stiff speed loop but moves its set-point with the measured string
torque so that the top drive behaves, for the string, like an endless continuation of the
drill pipe: a torsional wave of torque ``dT`` coming up the pipe meets a drive that gives way
at ``dT / Z`` and is absorbed instead of reflected (``Z`` the pipe's characteristic
impedance). Here::

    T     = k_pi x2 + c_pi (x1 - x3)                  string torque at the top drive
    T_m'  = (T - T_m) / tau_mean                      its running mean (low-pass)
    w_set = ref - (T - T_m) / z                       impedance-matched set-point
    u     = kp (w_set - x1) + ki integral(w_set - x1) stiff loop following w_set

Only the deviation of the torque from its running mean moves the set-point, so the mean
top-drive speed still equals the reference.

Tuning from the controller's model of the string:

* ``z = impedance_factor * Z``, ``Z = sqrt(k_pi J_pi)`` (:func:`baselines.string_modes.pipe_impedance`);
* ``tau_mean = mean_periods * 2 pi / w_s``: the mean follows the torque over about one
  stick-slip period, slow enough that the torque feedback acts in full at ``w_s``;
* the inner loop has the stiff tuning of :mod:`baselines.stiff_pi`
  (``kp = bandwidth_factor * Z``, ``ki = kp^2 / (4 damping_ratio^2 J_dt)``), so the drive
  follows ``w_set`` closely and its impedance is ``z`` at the stick-slip frequency.

For ``zribi2024``: ``z = 1,393.6 N m s/rad``, ``tau_mean = 10.04 s``, ``kp = 69,681 N m s/rad``,
``ki = 1.305e6 N m/rad``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from baselines.base import Gains
from baselines.speed_loop import DriveLimits, SpeedLoopController, SpeedLoopTuning
from baselines.string_modes import string_view
from drill_env.distributed import DistributedStringParameters
from drill_env.parameters import DrillStringParameters
from drill_env.validation import shown

__all__ = ["ZTorque", "ZTorqueGains"]


@dataclass(frozen=True)
class ZTorqueGains(Gains):
    """Tuning knobs of the impedance-matching controller.

    Attributes:
        impedance_factor: Torque-feedback impedance ``z`` as a multiple of the pipe impedance,
            dimensionless (in (0, 100]).
        mean_periods: Time constant of the torque mean in stick-slip periods, dimensionless
            (in (0, 1000]).
        bandwidth_factor: Inner loop ``kp`` as a multiple of the pipe impedance
            (in (0, 10,000]).
        damping_ratio: Damping ratio of the inner PI loop around the top-drive inertia
            (in (0, 100]).
        limits: Drive torque limits for anti-windup.
    """

    impedance_factor: float = 1.0
    mean_periods: float = 1.0
    bandwidth_factor: float = 50.0
    damping_ratio: float = 1.0
    limits: DriveLimits = field(default_factory=DriveLimits)

    def __post_init__(self) -> None:
        self._check_finite()
        self._check("impedance_factor", "(0, 100]", 0 < self.impedance_factor <= 100)
        self._check("mean_periods", "(0, 1000]", 0 < self.mean_periods <= 1000)
        self._check("bandwidth_factor", "(0, 10000]", 0 < self.bandwidth_factor <= 10_000)
        self._check("damping_ratio", "(0, 100]", 0 < self.damping_ratio <= 100)
        if not isinstance(self.limits, DriveLimits):
            raise TypeError(f"ZTorqueGains.limits must be a DriveLimits, got {shown(self.limits)}")


class ZTorque(SpeedLoopController):
    """Stiff speed loop with an impedance-matched torque feedback on its set-point (Z-Torque)."""

    name = "z_torque"
    rig_loop = True
    gains_type = ZTorqueGains

    def tuning(
        self, model: DrillStringParameters | DistributedStringParameters | None = None
    ) -> SpeedLoopTuning:
        """``z = impedance_factor Z``, ``tau_mean = mean_periods 2 pi / w_s`` and the stiff
        inner loop of :class:`baselines.stiff_pi.StiffPI`."""
        model = self.model if model is None else model
        m = string_view(model)
        g: ZTorqueGains = self.gains_for(model)
        z = m.impedance
        w_s = m.stick_slip_rad_s
        kp = g.bandwidth_factor * z
        ki = kp**2 / (4.0 * g.damping_ratio**2 * m.J_dt)
        return SpeedLoopTuning(
            kp=kp,
            ki=ki,
            z=g.impedance_factor * z,
            k_pi=m.k_pi,
            c_pi=m.c_pi,
            tau_mean_s=g.mean_periods * 2.0 * math.pi / w_s,
            pipe_impedance=z,
            stick_slip_rad_s=w_s,
        )
