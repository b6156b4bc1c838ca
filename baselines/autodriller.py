"""``autodriller``: the driller's loop on the axial input of ``DrillStringCoupled-v0``.

A rig's autodriller feeds the string (hook speed, or the applied force of a constant-hook-load
model) so as to hold the weight on bit at its set point, while other loops limit the rate of
penetration and the torque; the loop that asks for the least feed wins (min-select). Each loop
``i`` has a relative error ``e_i`` (positive: more feed allowed)::

    WOB:     e_w = (W_set - WOB) / W_set
    ROP:     e_r = (R_max - ROP) / R_ref          (only with rop_limit_rel > 0)
    torque:  e_t = (T_max - T_surface) / T_max    (only with torque_limit_nm > 0)

and proposes the command ``u + S (kp (e_i - e_i,prev) + ki e_i dt)`` (a PI in velocity form,
so switching between loops does not bump the command and nothing winds up); the command is
the least proposal, clipped to the env's range. ``S`` is the command's scale: the force set
point ``W_set`` (N) with the applied-force input, the reference rate of penetration ``R_ref``
(m/s) with the hook-speed input. ``W_set = wob_set_point_rel`` times the env's force set
point; ``R_ref`` is the env's steady rate of penetration at its set point.

With the applied-force input the mean weight on bit equals the mean applied force (axial
momentum), so the WOB loop alone only corrects the transients; its use there is the torque
and ROP limits. With the hook-speed input it is what keeps the bit on the rock at the weight
the driller wants when the rock changes (the string would drill off, or pile up, at a fixed
hook speed).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from drill_env.coupled_env import AxialMeasurement, AxialSetup
from drill_env.validation import check_finite_fields, check_unknown, require

__all__ = ["Autodriller", "AutodrillerGains"]


@dataclass(frozen=True)
class AutodrillerGains:
    """Tuning of the autodriller (relative errors, so the same gains suit any set point).

    Attributes:
        wob_set_point_rel: WOB set point over the env's force set point, - (in (0, 10]).
        kp: Proportional gain, command scales per unit relative error (in [0, 100]).
        ki: Integral gain, command scales per unit relative error and second, 1/s (in
            [0, 100]).
        rop_limit_rel: Largest rate of penetration over the env's reference one, - (0: no
            ROP limit; else in (0, 100]).
        torque_limit_nm: Largest surface torque, N m (0: no torque limit; else in (0, 1e6]).
    """

    wob_set_point_rel: float = 1.0
    kp: float = 0.5
    ki: float = 1.0
    rop_limit_rel: float = 0.0
    torque_limit_nm: float = 0.0

    def __post_init__(self) -> None:
        check_finite_fields(self, "AutodrillerGains.")
        for name, allowed, ok in (
            ("wob_set_point_rel", "(0, 10]", 0 < self.wob_set_point_rel <= 10),
            ("kp", "[0, 100]", 0 <= self.kp <= 100),
            ("ki", "[0, 100]", 0 <= self.ki <= 100),
            ("rop_limit_rel", "0 (off) or (0, 100]", 0 <= self.rop_limit_rel <= 100),
            ("torque_limit_nm", "0 (off) or (0, 1e6]", 0 <= self.torque_limit_nm <= 1e6),
        ):
            require(f"AutodrillerGains.{name}", getattr(self, name), allowed, ok)


class Autodriller:
    """The min-select autodriller (see the module docstring); an
    :class:`drill_env.coupled_env.AxialController` for ``force_loop="autodriller"``.

    Args:
        gains: The gains; defaults when omitted.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    name = "autodriller"

    def __init__(self, gains: AutodrillerGains | None = None, **overrides: Any) -> None:
        base = AutodrillerGains() if gains is None else gains
        if not isinstance(base, AutodrillerGains):
            raise TypeError(f"autodriller needs AutodrillerGains, got {type(base).__name__}")
        check_unknown(overrides, [f.name for f in dataclasses.fields(base)], "gain", self.name)
        self.gains = dataclasses.replace(base, **overrides) if overrides else base
        self._setup: AxialSetup | None = None
        self._previous: dict[str, float] = {}
        self.active = ""
        """The loop that set the last command (``wob``, ``rop`` or ``torque``)."""

    def __repr__(self) -> str:
        return f"Autodriller({self.gains!r})"

    def reset(self, setup: AxialSetup) -> None:
        """Start an episode: the env's input, set point and ranges."""
        self._setup = setup
        self._previous = {}
        self.active = ""

    def errors(self, m: AxialMeasurement) -> dict[str, float]:
        """The relative error of each active loop (positive: more feed allowed)."""
        s, g = self._setup, self.gains
        if s is None:
            raise RuntimeError("call reset(setup) before command()")
        wob_set = g.wob_set_point_rel * s.force_set_point_n
        errors = {"wob": (wob_set - m.wob_n) / wob_set}
        if g.rop_limit_rel > 0:
            errors["rop"] = (g.rop_limit_rel * s.rop_reference_m_s - m.rop_m_s) / max(
                s.rop_reference_m_s, 1e-12
            )
        if g.torque_limit_nm > 0:
            errors["torque"] = (g.torque_limit_nm - m.surface_torque_nm) / g.torque_limit_nm
        return errors

    def command(self, measurement: AxialMeasurement, dt_s: float) -> float:
        """The axial command (N or m/s) for the next ``dt_s`` seconds."""
        s, g = self._setup, self.gains
        if s is None:
            raise RuntimeError("call reset(setup) before command()")
        hook = s.axial_input == "hook_speed"
        scale = s.rop_reference_m_s if hook else g.wob_set_point_rel * s.force_set_point_n
        errors = self.errors(measurement)
        proposals = {
            name: measurement.command
            + scale * (g.kp * (e - self._previous.get(name, e)) + g.ki * e * dt_s)
            for name, e in errors.items()
        }
        self.active = min(proposals, key=lambda name: proposals[name])
        self._previous = errors
        return min(max(proposals[self.active], s.min_command), s.max_command)
