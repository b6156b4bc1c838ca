"""The lumped axial-torsional drill string with the regenerative (Richard-Germay-Detournay)
bit-rock law (docs/coupled-model.md).

The bottom-hole assembly is one rigid body with an axial position ``U`` (depth, down positive)
and an angle ``Phi``. A torsional spring ``C`` ties it to a top drive turning at ``Omega_0``; a
constant applied force ``W_0`` pushes it down. A drag bit with ``n`` blades cuts a depth per
blade ``d_n = U - R(Phi - 2 pi / n)``, where ``R(phi)`` is the rock surface the previous blade
left at angle ``phi``: a delay set by the bit's own rotation. The rock answers with a cutting
force and torque proportional to ``d_n`` and a set-valued frictional contact on the wear flats.
The dynamics are smooth by pieces between six regimes (:data:`REGIME_NAMES`): slipping down,
up, axially held or in the air, and stuck on or off the rock.

What is here:

* :class:`RgdParameters` and :data:`RGD_PRESETS` (``"rgd_a"``), with the derived constants;
* :func:`steady_state`: steady drilling in closed form;
* :func:`simulate`: the standard run (steady-drilling history, top drive at constant speed,
  constant applied force), compiled with numba, fixed-step RK4 with every regime switch
  located inside the step by regula falsi; it returns a :class:`CoupledTrace` sampled at every
  step;
* :func:`run_features`: the features of a trace over a window (:class:`RunFeatures`);
* :func:`rightmost_roots`, :func:`spectral_abscissa`, :func:`critical_speed_rad_s` and
  :func:`stability_map`: the linearised delay equation about steady drilling, its roots by
  Chebyshev collocation of the infinitesimal generator and Newton refinement; and
  :func:`simulated_map`, the stick-slip and bounce fractions on the same grid.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.validation import (
    InputTypeError,
    check_choice,
    check_finite_fields,
    check_int,
    check_interval,
    check_range,
    require,
    shown,
)

__all__ = [
    "REGIME_NAMES",
    "RGD_PRESETS",
    "STANDARD_DURATION_S",
    "STANDARD_POINTS",
    "STANDARD_WINDOW_S",
    "SURFACE_RULES",
    "FEATURE_SYMBOLS",
    "MAX_STEPS",
    "CoupledTrace",
    "RgdParameters",
    "RunFeatures",
    "SteadyState",
    "critical_speed_rad_s",
    "illinois_update",
    "lumped_string",
    "rightmost_roots",
    "run_features",
    "simulate",
    "simulated_map",
    "spectral_abscissa",
    "stable_speed_intervals",
    "stability_map",
    "standard_run",
    "steady_state",
]

# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RgdParameters:
    """Lumped axial-torsional string and RGD bit, in SI units.

    Attributes:
        blades: Number of blades ``n`` of the drag bit, -.
        bit_radius_m: Bit radius ``a``, m.
        intrinsic_energy_pa: Intrinsic specific energy of the rock ``epsilon``, Pa.
        force_ratio: Ratio ``zeta`` of vertical to horizontal cutting force, -.
        contact_strength_pa: Contact stress under the wear flats ``sigma``, Pa.
        wear_flat_length_m: Total wear-flat length ``l_tot`` (all blades), m.
        friction_coefficient: Bit-rock friction coefficient ``mu``, -.
        bit_geometry: Geometry coefficient ``gamma`` of the contact torque, -.
        axial_mass_kg: Axial mass ``M`` (BHA plus its share of the pipe), kg.
        inertia_kg_m2: Torsional inertia ``I`` (BHA plus its share of the pipe), kg m^2.
        torsional_stiffness_nm_rad: Torsional stiffness ``C`` of the drill pipe, N m/rad.
        torsional_damping_nms_rad: Viscous damping ``c_t`` of the rotation to ground,
            N m s/rad (pure RGD: 0).
        axial_damping_ns_m: Viscous damping ``c_a`` of the axial motion to ground, N s/m.
        axial_stiffness_n_m: Stiffness ``K`` of an axial spring to a hook moving at
            ``hook_speed_m_s``, N/m (RGD: 0, a constant applied force).
        hook_speed_m_s: Hook speed ``V_top`` (down positive), m/s; used only when ``K > 0``.
    """

    blades: int = 4
    bit_radius_m: float = 0.108
    intrinsic_energy_pa: float = 60e6
    force_ratio: float = 0.6
    contact_strength_pa: float = 60e6
    wear_flat_length_m: float = 4.8e-3
    friction_coefficient: float = 0.6
    bit_geometry: float = 1.0
    axial_mass_kg: float = 34_426.0
    inertia_kg_m2: float = 115.54
    torsional_stiffness_nm_rad: float = 938.1
    torsional_damping_nms_rad: float = 10.0
    axial_damping_ns_m: float = 0.0
    axial_stiffness_n_m: float = 0.0
    hook_speed_m_s: float = 0.0

    def __post_init__(self) -> None:
        check_int("blades", self.blades, 1)
        require("blades", self.blades, "an integer in [1, 64]", self.blades <= 64)
        check_finite_fields(self)
        for name in (
            "bit_radius_m",
            "intrinsic_energy_pa",
            "force_ratio",
            "axial_mass_kg",
            "inertia_kg_m2",
            "torsional_stiffness_nm_rad",
        ):
            require(name, getattr(self, name), "> 0", getattr(self, name) > 0)
        for name in (
            "contact_strength_pa",
            "wear_flat_length_m",
            "friction_coefficient",
            "bit_geometry",
            "torsional_damping_nms_rad",
            "axial_damping_ns_m",
            "axial_stiffness_n_m",
        ):
            require(name, getattr(self, name), ">= 0", getattr(self, name) >= 0)

    @property
    def k_a(self) -> float:
        """Cutting weight per unit depth of cut per blade ``n a zeta epsilon``, N/m."""
        return self.blades * self.bit_radius_m * self.force_ratio * self.intrinsic_energy_pa

    @property
    def k_t(self) -> float:
        """Cutting torque per unit depth of cut per blade ``n a^2 epsilon / 2``, N."""
        return self.blades * self.bit_radius_m**2 * self.intrinsic_energy_pa / 2.0

    @property
    def contact_force_n(self) -> float:
        """Fully mobilised wear-flat force ``W_f_bar = a l_tot sigma``, N."""
        return self.bit_radius_m * self.wear_flat_length_m * self.contact_strength_pa

    @property
    def contact_arm_m(self) -> float:
        """Contact torque arm ``t_f = mu gamma a / 2`` (``T_f = t_f W_f``), m."""
        return self.friction_coefficient * self.bit_geometry * self.bit_radius_m / 2.0

    @property
    def contact_torque_nm(self) -> float:
        """Fully mobilised contact torque ``T_f_bar = t_f W_f_bar``, N m."""
        return self.contact_arm_m * self.contact_force_n

    @property
    def blade_angle_rad(self) -> float:
        """Angle between two blades ``2 pi / n``, rad."""
        return 2.0 * math.pi / self.blades


def lumped_string(
    pipe_length_m: float = 1000.0,
    collar_length_m: float = 200.0,
    pipe_radii_m: tuple[float, float] = (0.0635, 0.0540),
    collar_radii_m: tuple[float, float] = (0.0762, 0.0286),
    shear_modulus_pa: float = 77e9,
    density_kg_m3: float = 8000.0,
) -> tuple[float, float, float]:
    """Axial mass, torsional inertia and stiffness of a pipe-plus-collars string lumped at
    the bit: ``M = rho A_b L_b + rho A_p L_p / 3``, ``I = rho J_b L_b + rho J_p L_p / 3`` and
    ``C = G J_p / L_p`` (``A``: cross-section area, ``J``: polar moment of area).

    Args:
        pipe_length_m, collar_length_m: Lengths of the drill pipe and the collars, m.
        pipe_radii_m, collar_radii_m: (outer, inner) radii, m.
        shear_modulus_pa: Shear modulus ``G`` of steel, Pa.
        density_kg_m3: Density ``rho`` of steel, kg/m^3.

    Returns:
        ``(M, I, C)`` in kg, kg m^2 and N m/rad.
    """

    def area(radii: tuple[float, float]) -> float:
        return math.pi * (radii[0] ** 2 - radii[1] ** 2)

    def polar(radii: tuple[float, float]) -> float:
        return math.pi / 2.0 * (radii[0] ** 4 - radii[1] ** 4)

    mass = density_kg_m3 * (
        area(collar_radii_m) * collar_length_m + area(pipe_radii_m) * pipe_length_m / 3.0
    )
    inertia = density_kg_m3 * (
        polar(collar_radii_m) * collar_length_m + polar(pipe_radii_m) * pipe_length_m / 3.0
    )
    stiffness = shear_modulus_pa * polar(pipe_radii_m) / pipe_length_m
    return mass, inertia, stiffness


def _rgd_a() -> RgdParameters:
    mass, inertia, stiffness = lumped_string()
    return RgdParameters(
        axial_mass_kg=mass, inertia_kg_m2=inertia, torsional_stiffness_nm_rad=stiffness
    )


RGD_PRESETS: Final[dict[str, RgdParameters]] = {
    # RGD-A: the bit of Aarsnes & Aamo's code, 4.8 mm of wear flats, a 1000 m pipe on 200 m of
    # collars lumped at the bit, 10 N m s/rad of torsional damping (docs/coupled-model.md).
    "rgd_a": _rgd_a(),
}
"""Named parameter sets of the coupled string."""

SURFACE_RULES: Final = ("max", "delay")
"""Rules that update the rock surface as the bit passes: ``"max"`` keeps the deeper of the
bit and the old surface, ``"delay"`` takes the bit's depth (the textbook delay form)."""

REGIME_NAMES: Final = ("down", "up", "hold", "air", "stuck", "stuck_air")
"""Regimes by code: slipping on the rock moving down, up, axially held, slipping off the
rock, stuck on the rock, stuck off the rock."""

_DOWN, _UP, _HOLD, _AIR, _STUCK, _STUCK_AIR = range(6)


def _resolve(parameters: str | RgdParameters, name: str = "parameters") -> RgdParameters:
    """The RGD bit's parameters: ``parameters`` itself or the preset it names; errors name the
    keyword ``name`` that gave it."""
    if isinstance(parameters, RgdParameters):
        return parameters
    if isinstance(parameters, str):
        check_choice(name, parameters, RGD_PRESETS, "preset")
        return RGD_PRESETS[parameters]
    raise InputTypeError(
        f"{name} must be a preset name {sorted(RGD_PRESETS)} or an RgdParameters, got "
        f"{shown(parameters)}"
    )


# ---------------------------------------------------------------------------------------------
# Steady drilling
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SteadyState:
    """Steady drilling at a top-drive speed and applied force (``K = 0``).

    Attributes:
        depth_of_cut_m: Depth of cut per blade ``d_0``, m.
        rate_of_penetration_m_s: Rate of penetration ``V_0``, m/s.
        torque_on_bit_nm: Torque on bit ``T_0``, N m.
        weight_on_bit_n: Weight on bit ``W_0 - c_a V_0``, N.
        twist_rad: Steady twist of the string ``theta_0``, rad.
        delay_s: Nominal delay ``tau = 2 pi / (n Omega_0)``, s.
        surface_slope_m_rad: ``r = V_0 / Omega_0``, m/rad.
    """

    depth_of_cut_m: float
    rate_of_penetration_m_s: float
    torque_on_bit_nm: float
    weight_on_bit_n: float
    twist_rad: float
    delay_s: float
    surface_slope_m_rad: float


def _check_operating_point(p: RgdParameters, speed: object, force: object) -> tuple[float, float]:
    omega0 = check_range("top_drive_speed_rad_s", speed, 0.0, 1e3)
    require("top_drive_speed_rad_s", speed, "(0, 1000] rad/s", omega0 > 0)
    w0 = check_range("applied_force_n", force, 0.0, 1e8)
    require(
        "applied_force_n",
        force,
        f"({p.contact_force_n:g}, 1e+08] N: above the wear-flat force W_f_bar, or the bit "
        "does not drill",
        w0 > p.contact_force_n,
    )
    return omega0, w0


def steady_state(
    parameters: str | RgdParameters, top_drive_speed_rad_s: float, applied_force_n: float
) -> SteadyState:
    """Steady drilling in closed form: ``d_0 = (W_0 - W_f_bar) / (k_a + c_a n Omega_0 / 2 pi)``,
    ``V_0 = n Omega_0 d_0 / 2 pi``, ``T_0 = k_t d_0 + T_f_bar``, ``theta_0 = (T_0 + c_t
    Omega_0) / C``.

    Args:
        parameters: A preset name of :data:`RGD_PRESETS` or an :class:`RgdParameters`.
        top_drive_speed_rad_s: Top-drive speed ``Omega_0`` in (0, 1000], rad/s.
        applied_force_n: Applied axial force ``W_0``, N; above ``W_f_bar``.

    Raises:
        ValueError: naming the argument when it is out of range.
    """
    p = _resolve(parameters)
    omega0, w0 = _check_operating_point(p, top_drive_speed_rad_s, applied_force_n)
    n = p.blades
    d0 = (w0 - p.contact_force_n) / (p.k_a + p.axial_damping_ns_m * n * omega0 / (2 * math.pi))
    v0 = n * omega0 * d0 / (2 * math.pi)
    t0 = p.k_t * d0 + p.contact_torque_nm
    return SteadyState(
        depth_of_cut_m=d0,
        rate_of_penetration_m_s=v0,
        torque_on_bit_nm=t0,
        weight_on_bit_n=w0 - p.axial_damping_ns_m * v0,
        twist_rad=(t0 + p.torsional_damping_nms_rad * omega0) / p.torsional_stiffness_nm_rad,
        delay_s=2 * math.pi / (n * omega0),
        surface_slope_m_rad=v0 / omega0,
    )


# ---------------------------------------------------------------------------------------------
# Compiled simulation
# ---------------------------------------------------------------------------------------------

# Indices of the kernel's parameter vector.
_P_M, _P_I, _P_C, _P_CT, _P_CA, _P_K, _P_VTOP, _P_W0, _P_OM0, _P_TH0 = range(10)
_P_KA, _P_KT, _P_WF, _P_ARM, _P_TF, _P_BLADE, _P_DELAY_RULE, _P_SPACING = range(10, 18)
_N_P = 18

_SPACING_FRACTION: Final = 1e-5
"""The surface is sampled at most every ``1e-5`` blade angles of bit rotation."""
_RING_SPAN: Final = 2.0
"""The surface ring holds at least this many blade angles of rotation behind the bit."""
_MAX_SWITCHES: Final = 32
"""Regime switches allowed within one step before the step is finished without them."""
_LOCATE_TOLERANCE: Final = 1e-13
"""Switches are located to this fraction of the step."""


@njit(cache=True)
def _surface(phi_d: float, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray) -> float:
    """Rock depth ``R(phi_d)``, m, linearly interpolated in angle between the stored samples.

    ``ring`` holds the logical indices ``(first, last, cursor)`` of the ring buffers
    ``ring_phi`` (rad) and ``ring_r`` (m); the cursor is moved to the sample at or below
    ``phi_d``."""
    cap = ring_phi.shape[0]
    first = ring[0]
    last = ring[1]
    j = ring[2]
    while j > first and ring_phi[j % cap] > phi_d:
        j -= 1
    while j + 1 < last and ring_phi[(j + 1) % cap] <= phi_d:
        j += 1
    if j >= last:
        j = last - 1
    ring[2] = j
    p0 = ring_phi[j % cap]
    p1 = ring_phi[(j + 1) % cap]
    r0 = ring_r[j % cap]
    r1 = ring_r[(j + 1) % cap]
    return r0 + (r1 - r0) * (phi_d - p0) / (p1 - p0)


@njit(cache=True)
def _record(
    phi: float,
    u: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> None:
    """Store the rock surface the bit leaves at angle ``phi`` (rad) when the bit (at depth
    ``u``, m) turned at least the sampling spacing since the last sample; the oldest sample is
    overwritten when the ring is full."""
    cap = ring_phi.shape[0]
    last = ring[1]
    if phi - ring_phi[last % cap] < p[_P_SPACING]:
        return
    if p[_P_DELAY_RULE] > 0.5:
        depth = u
    else:
        depth = max(u, _surface(phi - p[_P_BLADE], ring_phi, ring_r, ring))
    last += 1
    ring[1] = last
    if last - ring[0] + 1 > cap:
        ring[0] = last - cap + 1
        if ring[2] < ring[0]:
            ring[2] = ring[0]
    ring_phi[last % cap] = phi
    ring_r[last % cap] = depth


@njit(cache=True)
def _from_rest(dn: float, f_ax: float, p: np.ndarray) -> int:
    """Axial sub-regime of a bit at ``V = 0`` on the rock, from ``F_free = F_ax - k_a d_n``."""
    f_free = f_ax - p[_P_KA] * dn
    if f_free > p[_P_WF]:
        return _DOWN
    if f_free >= 0.0:
        return _HOLD
    return _UP


@njit(cache=True)
def bit_load(regime: int, dn: float, f_ax: float, ts: float, p: np.ndarray) -> tuple[float, float]:
    """The RGD bit law: weight and torque on bit ``(W, T)`` (N, N m) in ``regime`` from the
    depth of cut per blade ``dn`` (m), the applied axial force ``f_ax`` (N) and the string
    torque on the bit ``ts`` (N m); reactions while stuck or held, zero off the rock. ``p`` is
    a kernel parameter vector (its bit entries)."""
    if regime == _DOWN:
        return p[_P_KA] * dn + p[_P_WF], p[_P_KT] * dn + p[_P_TF]
    if regime == _UP:
        return p[_P_KA] * dn, p[_P_KT] * dn
    if regime == _HOLD:
        return f_ax, p[_P_KT] * dn + p[_P_ARM] * (f_ax - p[_P_KA] * dn)
    if regime == _STUCK:
        return f_ax, ts
    return 0.0, 0.0


@njit(cache=True)
def switching_functions(
    g: np.ndarray, regime: int, dn: float, f_ax: float, ts: float, v: float, om: float,
    p: np.ndarray,
) -> None:  # fmt: skip
    """Write the switching functions of ``regime`` into ``g`` (4,): the regime holds while
    each is positive and a switch happens where one turns negative (unused entries: 1).
    ``v`` (m/s) and ``om`` (rad/s) are the bit's axial and angular speeds."""
    g[0] = 1.0
    g[1] = 1.0
    g[2] = 1.0
    g[3] = 1.0
    if regime == _DOWN:
        g[0] = om  # stick
        g[1] = v  # V -> 0-
        g[2] = dn  # lift-off
    elif regime == _UP:
        g[0] = om
        g[1] = -v  # V -> 0+
        g[2] = dn
    elif regime == _HOLD:
        f_free = f_ax - p[_P_KA] * dn
        g[0] = om
        g[1] = p[_P_WF] - f_free  # F_free above W_f_bar
        g[2] = f_free  # F_free below 0
        g[3] = dn
    elif regime == _AIR:
        g[0] = om
        g[1] = -dn  # landing
    elif regime == _STUCK:
        g[0] = p[_P_KT] * max(dn, 0.0) + p[_P_TF] - ts  # release: T_s above the capacity
    else:
        g[0] = -dn  # landing while stuck
        g[1] = -ts  # release: T_s > 0


@njit(cache=True)
def stop_rule(
    dn: float, f_rest: float, ts: float, v: float, om: float, p: np.ndarray
) -> tuple[int, float, float, float]:
    """The bit reaches ``Omega = 0`` (rules S1, S4 and the immediate release): ``(regime, V,
    Omega, kinetic energy removed, J)``; ``f_rest`` is the applied force at ``V = 0`` (N)."""
    loss = 0.5 * p[_P_I] * om * om
    if dn >= 0.0:
        loss += 0.5 * p[_P_M] * v * v
        if ts > p[_P_KT] * dn + p[_P_TF]:
            return _from_rest(dn, f_rest, p), 0.0, 0.0, loss
        return _STUCK, 0.0, 0.0, loss
    if ts > 0.0:
        return _AIR, v, 0.0, loss
    return _STUCK_AIR, v, 0.0, loss


@njit(cache=True)
def switch_rule(
    regime: int, which: int, dn: float, f_rest: float, ts: float, v: float, om: float,
    p: np.ndarray,
) -> tuple[int, float, float, float]:  # fmt: skip
    """Apply switch ``which`` (an index of :func:`switching_functions`) of ``regime``: ``(new
    regime, V, Omega, kinetic energy removed, J)``, the state set on the switching surface."""
    if regime != _STUCK and regime != _STUCK_AIR and which == 0:
        return stop_rule(dn, f_rest, ts, v, om, p)
    if regime in (_DOWN, _UP):
        if which == 2:
            return _AIR, v, om, 0.0
        loss = 0.5 * p[_P_M] * v * v
        new = _from_rest(dn, f_rest, p)
        if regime == _DOWN and new == _DOWN:
            new = _HOLD  # V fell through 0 with F_free at W_f_bar: hold
        if regime == _UP and new == _UP:
            new = _HOLD
        return new, 0.0, om, loss
    if regime == _HOLD:
        if which == 1:
            return _DOWN, 0.0, om, 0.0
        if which == 2:
            return _UP, 0.0, om, 0.0
        return _AIR, 0.0, om, 0.0
    if regime == _AIR:  # landing, no impulse
        if v > 0.0:
            return _DOWN, v, om, 0.0
        if v < 0.0:
            return _UP, v, om, 0.0
        return _from_rest(dn, f_rest, p), 0.0, om, 0.0
    if regime == _STUCK:  # release
        return _from_rest(dn, f_rest, p), 0.0, 0.0, 0.0
    # stuck off the rock
    if which == 0:  # landing while stuck: inelastic axial stop
        loss = 0.5 * p[_P_M] * v * v
        if ts > p[_P_KT] * max(dn, 0.0) + p[_P_TF]:
            return _from_rest(max(dn, 0.0), f_rest, p), 0.0, 0.0, loss
        return _STUCK, 0.0, 0.0, loss
    return _AIR, v, 0.0, 0.0


@njit(cache=True)
def _forces(
    regime: int,
    t: float,
    u: float,
    v: float,
    phi: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> tuple[float, float, float, float, float]:
    """``(d_n, F_ax, T_s, W, T)`` in regime ``regime`` at time ``t`` (s), depth ``u`` (m),
    axial speed ``v`` (m/s) and angle ``phi`` (rad): depth of cut per blade (m), applied axial
    force (N), string torque (N m), weight and torque on bit (N, N m; reactions when stuck)."""
    dn = u - _surface(phi - p[_P_BLADE], ring_phi, ring_r, ring)
    f_ax = p[_P_W0] + p[_P_K] * (p[_P_VTOP] * t - u) - p[_P_CA] * v
    ts = p[_P_C] * (p[_P_OM0] * t + p[_P_TH0] - phi)
    w, tq = bit_load(regime, dn, f_ax, ts, p)
    return dn, f_ax, ts, w, tq


@njit(cache=True)
def _rhs(
    regime: int,
    t: float,
    u: float,
    v: float,
    phi: float,
    om: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> tuple[float, float, float, float]:
    """Time derivatives of ``(U, V, Phi, Omega)`` in the frozen regime ``regime``."""
    if regime == _STUCK:
        return 0.0, 0.0, 0.0, 0.0
    dn, f_ax, ts, w, tq = _forces(regime, t, u, v, phi, p, ring_phi, ring_r, ring)
    if regime == _STUCK_AIR:
        return v, f_ax / p[_P_M], 0.0, 0.0
    dom = (ts - p[_P_CT] * om - tq) / p[_P_I]
    if regime == _HOLD:
        return 0.0, 0.0, om, dom
    return v, (f_ax - w) / p[_P_M], om, dom


@njit(cache=True)
def _rk4(
    regime: int,
    t: float,
    u: float,
    v: float,
    phi: float,
    om: float,
    dt: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> tuple[float, float, float, float]:
    """One classical Runge-Kutta step of ``dt`` (s) in the frozen regime; the stages read the
    surface at their own ``(U, Phi)``."""
    a1, b1, c1, d1 = _rhs(regime, t, u, v, phi, om, p, ring_phi, ring_r, ring)
    hh = 0.5 * dt
    a2, b2, c2, d2 = _rhs(
        regime, t + hh, u + hh * a1, v + hh * b1, phi + hh * c1, om + hh * d1, p, ring_phi,
        ring_r, ring,
    )  # fmt: skip
    a3, b3, c3, d3 = _rhs(
        regime, t + hh, u + hh * a2, v + hh * b2, phi + hh * c2, om + hh * d2, p, ring_phi,
        ring_r, ring,
    )  # fmt: skip
    a4, b4, c4, d4 = _rhs(
        regime, t + dt, u + dt * a3, v + dt * b3, phi + dt * c3, om + dt * d3, p, ring_phi,
        ring_r, ring,
    )  # fmt: skip
    s = dt / 6.0
    return (
        u + s * (a1 + 2.0 * a2 + 2.0 * a3 + a4),
        v + s * (b1 + 2.0 * b2 + 2.0 * b3 + b4),
        phi + s * (c1 + 2.0 * c2 + 2.0 * c3 + c4),
        om + s * (d1 + 2.0 * d2 + 2.0 * d3 + d4),
    )


@njit(cache=True)
def _events(
    g: np.ndarray,
    regime: int,
    t: float,
    u: float,
    v: float,
    phi: float,
    om: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> None:
    """Write the switching functions of ``regime`` at this state into ``g`` (4,)."""
    dn, f_ax, ts, w, tq = _forces(regime, t, u, v, phi, p, ring_phi, ring_r, ring)
    switching_functions(g, regime, dn, f_ax, ts, v, om, p)


@njit(cache=True)
def _stop(
    t: float,
    u: float,
    v: float,
    phi: float,
    om: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> tuple[int, float, float, float]:
    """The bit reaches ``Omega = 0``: :func:`stop_rule` at this state."""
    dn, f_rest, ts, w, tq = _forces(_STUCK, t, u, 0.0, phi, p, ring_phi, ring_r, ring)
    return stop_rule(dn, f_rest, ts, v, om, p)


@njit(cache=True)
def _switch(
    regime: int,
    which: int,
    t: float,
    u: float,
    v: float,
    phi: float,
    om: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> tuple[int, float, float, float]:
    """Apply switch ``which`` of ``regime`` at this state (:func:`switch_rule`)."""
    dn, f_rest, ts, w, tq = _forces(regime, t, u, 0.0, phi, p, ring_phi, ring_r, ring)
    return switch_rule(regime, which, dn, f_rest, ts, v, om, p)


@njit(cache=True, inline="always")
def illinois_update(
    a: float, b: float, fa: float, fb: float, side: int, c: float, fc: float
) -> tuple[float, float, float, float, int]:
    """One bracket update of the Illinois regula falsi: the new point ``c`` (value ``fc``,
    non-zero) replaces the end of the bracket ``[a, b]`` with the same sign, and the value of
    an end kept twice in a row is halved. Returns ``(a, b, fa, fb, side)``."""
    if fc < 0.0:
        if side == -1:
            fa *= 0.5
        return a, c, fa, fc, -1
    if side == 1:
        fb *= 0.5
    return c, b, fc, fb, 1


@njit(cache=True)
def _locate(
    which: int,
    regime: int,
    t: float,
    u: float,
    v: float,
    phi: float,
    om: float,
    dt: float,
    g_start: float,
    g_end: float,
    tolerance: float,
    g: np.ndarray,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> float:
    """Time (s, from ``t``) at which switching function ``which`` turns negative along the RK4
    solution, by regula falsi (Illinois); the returned end lies on the far side."""
    a = 0.0
    fa = g_start
    b = dt
    fb = g_end
    side = 0
    for _ in range(200):
        if b - a <= tolerance:
            break
        c = b - fb * (b - a) / (fb - fa)
        if not (a < c < b):
            c = 0.5 * (a + b)
        uc, vc, pc, oc = _rk4(regime, t, u, v, phi, om, c, p, ring_phi, ring_r, ring)
        _events(g, regime, t + c, uc, vc, pc, oc, p, ring_phi, ring_r, ring)
        fc = g[which]
        if not (fc < 0.0 or fc > 0.0):
            return c
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
    return b


@njit(cache=True)
def _initial_regime(
    u: float,
    v: float,
    phi: float,
    om: float,
    p: np.ndarray,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
) -> tuple[int, float]:
    """Regime of the initial state ``(U, V, Phi, Omega)`` at ``t = 0``, and its ``V``."""
    if om <= 0.0:
        regime, v0, om0, loss = _stop(0.0, u, v, phi, 0.0, p, ring_phi, ring_r, ring)
        return regime, v0
    dn, f_ax, ts, w, tq = _forces(_DOWN, 0.0, u, v, phi, p, ring_phi, ring_r, ring)
    if dn < 0.0:
        return _AIR, v
    if v > 0.0:
        return _DOWN, v
    if v < 0.0:
        return _UP, v
    return _from_rest(dn, f_ax, p), 0.0


_S_LOSS, _S_SWITCHES, _S_CROWDED, _S_DONE = range(4)


@njit(cache=True)
def _simulate_kernel(
    p: np.ndarray,
    n_steps: int,
    h: float,
    om_start: float,
    v_start: float,
    ring_phi: np.ndarray,
    ring_r: np.ndarray,
    ring: np.ndarray,
    out_u: np.ndarray,
    out_v: np.ndarray,
    out_phi: np.ndarray,
    out_om: np.ndarray,
    out_w: np.ndarray,
    out_tq: np.ndarray,
    out_dn: np.ndarray,
    out_regime: np.ndarray,
    out_loss: np.ndarray,
    stats: np.ndarray,
) -> None:
    """Run ``n_steps`` steps of ``h`` (s) from ``U = Phi = 0``, ``Omega = om_start``,
    ``V = v_start`` and write the state, forces, depth of cut and regime at every step end
    (index 0: ``t = 0``). ``stats``: kinetic energy removed by switches (J), switches, steps
    that hit the switch limit, steps completed (fewer than ``n_steps`` when the state stopped
    being finite)."""
    g0 = np.empty(4)
    g1 = np.empty(4)
    gc = np.empty(4)
    t = 0.0
    u = 0.0
    phi = 0.0
    om = om_start
    regime, v = _initial_regime(u, v_start, phi, om, p, ring_phi, ring_r, ring)
    if regime in (_STUCK, _STUCK_AIR):
        om = 0.0
    tolerance = _LOCATE_TOLERANCE * h
    dn, f_ax, ts, w, tq = _forces(regime, t, u, v, phi, p, ring_phi, ring_r, ring)
    out_u[0], out_v[0], out_phi[0], out_om[0] = u, v, phi, om
    out_w[0], out_tq[0], out_dn[0], out_regime[0] = w, tq, dn, regime
    out_loss[0] = 0.0
    for k in range(n_steps):
        t_end = (k + 1) * h
        switches = 0
        while True:
            dt = t_end - t
            if dt <= 0.0:
                break
            _events(g0, regime, t, u, v, phi, om, p, ring_phi, ring_r, ring)
            live = switches < _MAX_SWITCHES
            if live:
                now = -1
                for i in range(4):
                    if g0[i] < 0.0:
                        now = i
                        break
                if now >= 0:  # inconsistent at the start: switch at once
                    regime, v, om, loss = _switch(
                        regime, now, t, u, v, phi, om, p, ring_phi, ring_r, ring
                    )
                    stats[_S_LOSS] += loss
                    stats[_S_SWITCHES] += 1
                    switches += 1
                    continue
            u1, v1, p1, o1 = _rk4(regime, t, u, v, phi, om, dt, p, ring_phi, ring_r, ring)
            _events(g1, regime, t_end, u1, v1, p1, o1, p, ring_phi, ring_r, ring)
            first = -1
            when = dt
            if live:
                for i in range(4):
                    if g0[i] > 0.0 and g1[i] < 0.0:
                        at = _locate(
                            i, regime, t, u, v, phi, om, dt, g0[i], g1[i], tolerance, gc, p,
                            ring_phi, ring_r, ring,
                        )  # fmt: skip
                        if first < 0 or at < when:
                            first = i
                            when = at
            else:
                stats[_S_CROWDED] += 1
            if first < 0:
                late = -1
                if live:
                    for i in range(4):
                        if g0[i] == 0.0 and g1[i] < 0.0:  # left the surface on the wrong side
                            late = i
                            break
                t, u, v, phi, om = t_end, u1, v1, p1, o1
                _record(phi, u, p, ring_phi, ring_r, ring)
                if late >= 0:
                    regime, v, om, loss = _switch(
                        regime, late, t, u, v, phi, om, p, ring_phi, ring_r, ring
                    )
                    stats[_S_LOSS] += loss
                    stats[_S_SWITCHES] += 1
                break
            u, v, phi, om = _rk4(regime, t, u, v, phi, om, when, p, ring_phi, ring_r, ring)
            t = t_end if when >= dt else t + when
            _record(phi, u, p, ring_phi, ring_r, ring)
            regime, v, om, loss = _switch(
                regime, first, t, u, v, phi, om, p, ring_phi, ring_r, ring
            )
            stats[_S_LOSS] += loss
            stats[_S_SWITCHES] += 1
            switches += 1
        if not (math.isfinite(u) and math.isfinite(v) and math.isfinite(phi) and math.isfinite(om)):
            return
        dn, f_ax, ts, w, tq = _forces(regime, t, u, v, phi, p, ring_phi, ring_r, ring)
        out_u[k + 1], out_v[k + 1], out_phi[k + 1], out_om[k + 1] = u, v, phi, om
        out_w[k + 1], out_tq[k + 1], out_dn[k + 1], out_regime[k + 1] = w, tq, dn, regime
        out_loss[k + 1] = stats[_S_LOSS]
        stats[_S_DONE] = k + 1


def _kernel_parameters(
    p: RgdParameters, omega0: float, w0: float, twist: float, surface: str
) -> npt.NDArray[np.float64]:
    vector = np.zeros(_N_P)
    vector[_P_M] = p.axial_mass_kg
    vector[_P_I] = p.inertia_kg_m2
    vector[_P_C] = p.torsional_stiffness_nm_rad
    vector[_P_CT] = p.torsional_damping_nms_rad
    vector[_P_CA] = p.axial_damping_ns_m
    vector[_P_K] = p.axial_stiffness_n_m
    vector[_P_VTOP] = p.hook_speed_m_s
    vector[_P_W0] = w0
    vector[_P_OM0] = omega0
    vector[_P_TH0] = twist
    vector[_P_KA] = p.k_a
    vector[_P_KT] = p.k_t
    vector[_P_WF] = p.contact_force_n
    vector[_P_ARM] = p.contact_arm_m
    vector[_P_TF] = p.contact_torque_nm
    vector[_P_BLADE] = p.blade_angle_rad
    vector[_P_DELAY_RULE] = 1.0 if surface == "delay" else 0.0
    vector[_P_SPACING] = _SPACING_FRACTION * p.blade_angle_rad
    return vector


MAX_STEPS: Final = 20_000_000
"""Most steps one :func:`simulate` call records (eight arrays of this length)."""


@dataclass(frozen=True)
class CoupledTrace:
    """One run of :func:`simulate`, sampled at ``t = 0`` and at the end of every step (``m``
    samples).

    Attributes:
        time_s: Sample times, (m,), s.
        bit_speed_rad_s: Bit angular speed ``Omega``, (m,), rad/s.
        axial_speed_m_s: Bit axial speed ``V`` (down positive), (m,), m/s.
        depth_m: Bit depth ``U`` from its start, (m,), m.
        bit_angle_rad: Bit angle ``Phi``, (m,), rad.
        weight_on_bit_n: Weight on bit ``W`` (the reaction while stuck or held), (m,), N.
        torque_on_bit_nm: Torque on bit ``T`` (the reaction while stuck), (m,), N m.
        depth_of_cut_m: Depth of cut per blade ``d_n`` (negative off the rock), (m,), m.
        regime: Regime code (an index of :data:`REGIME_NAMES`), (m,), int8.
        stuck: The bit does not rotate, (m,), bool.
        off_bottom: The bit is off the rock (``d_n < 0``), (m,), bool.
        axial_hold: The bit rotates on the rock with ``V = 0`` held by the wear flats, (m,),
            bool.
        top_drive_speed_rad_s: Top-drive speed ``Omega_0``, rad/s.
        applied_force_n: Applied force ``W_0``, N.
        steady: Steady drilling at this point (the history before ``t = 0``).
        parameters: The parameter set.
        step_s: Integration step, s.
        surface: Surface rule, ``"max"`` or ``"delay"``.
        switch_loss_j: Kinetic energy removed so far by the velocity resets at switches (the
            inelastic axial stop when the bit sticks on or lands on the rock), (m,), J.
        switches: Number of regime switches.
        diverged: The state stopped being finite; the trace ends at the last finite sample.
    """

    time_s: npt.NDArray[np.float64]
    bit_speed_rad_s: npt.NDArray[np.float64]
    axial_speed_m_s: npt.NDArray[np.float64]
    depth_m: npt.NDArray[np.float64]
    bit_angle_rad: npt.NDArray[np.float64]
    weight_on_bit_n: npt.NDArray[np.float64]
    torque_on_bit_nm: npt.NDArray[np.float64]
    depth_of_cut_m: npt.NDArray[np.float64]
    regime: npt.NDArray[np.int8]
    stuck: npt.NDArray[np.bool_]
    off_bottom: npt.NDArray[np.bool_]
    axial_hold: npt.NDArray[np.bool_]
    top_drive_speed_rad_s: float
    applied_force_n: float
    steady: SteadyState
    parameters: RgdParameters
    step_s: float
    surface: str
    switch_loss_j: npt.NDArray[np.float64]
    switches: int
    diverged: bool

    @property
    def string_torque_nm(self) -> npt.NDArray[np.float64]:
        """Torque in the string ``C (Omega_0 t + theta_0 - Phi)``, (m,), N m."""
        omega0, twist = self.top_drive_speed_rad_s, self.steady.twist_rad
        c = self.parameters.torsional_stiffness_nm_rad
        return c * (omega0 * self.time_s + twist - self.bit_angle_rad)


def simulate(
    parameters: str | RgdParameters,
    top_drive_speed_rad_s: float,
    applied_force_n: float,
    duration_s: float,
    *,
    initial_bit_speed_rad_s: float | None = None,
    initial_axial_speed_m_s: float | None = None,
    step_s: float = 1e-4,
    surface: str = "max",
) -> CoupledTrace:
    """The standard run: steady drilling before ``t = 0`` (rock surface ``R(phi) = r phi``),
    then the top drive at ``Omega_0 t + theta_0`` and the applied force ``W_0``, from
    ``U = Phi = 0``.

    Fixed-step RK4 with the regime frozen in each step; every regime switch (stick, release,
    ``V`` through 0, ``F_free`` leaving ``[0, W_f_bar]``, lift-off, landing) is located inside
    the step by regula falsi on the RK4 solution to ``1e-13`` of the step and the rest of the
    step is taken in the new regime. The rock surface is stored against the bit angle.

    Args:
        parameters: A preset name of :data:`RGD_PRESETS` or an :class:`RgdParameters`.
        top_drive_speed_rad_s: Top-drive speed ``Omega_0`` in (0, 1000], rad/s.
        applied_force_n: Applied axial force ``W_0`` above ``W_f_bar``, N.
        duration_s: Simulated time, s (at most ``MAX_STEPS`` steps).
        initial_bit_speed_rad_s: ``Omega(0)`` in [0, 1000] rad/s; default ``0.9 Omega_0``
            (initial condition "a").
        initial_axial_speed_m_s: ``V(0)`` in [-10, 10] m/s; default the steady ``V_0``.
        step_s: Integration step in [1e-7, 1e-4], s.
        surface: ``"max"`` (default) or ``"delay"`` (:data:`SURFACE_RULES`).

    Returns:
        The trace at every step.

    Raises:
        ValueError, TypeError: naming the argument and its allowed range.
    """
    p = _resolve(parameters)
    omega0, w0 = _check_operating_point(p, top_drive_speed_rad_s, applied_force_n)
    duration = check_range("duration_s", duration_s, 0.0, 1e6)
    require("duration_s", duration_s, "(0, 1e+06] s", duration > 0)
    h = check_range("step_s", step_s, 1e-7, 1e-4)
    check_choice("surface", surface, SURFACE_RULES, "surface rule")
    n_steps = max(1, math.ceil(duration / h - 1e-9))
    require(
        "duration_s",
        duration_s,
        f"at most {MAX_STEPS} steps of step_s = {h:g} s ({MAX_STEPS * h:g} s)",
        n_steps <= MAX_STEPS,
    )
    steady = steady_state(p, omega0, w0)
    om_start = (
        0.9 * omega0
        if initial_bit_speed_rad_s is None
        else check_range("initial_bit_speed_rad_s", initial_bit_speed_rad_s, 0.0, 1e3)
    )
    v_start = (
        steady.rate_of_penetration_m_s
        if initial_axial_speed_m_s is None
        else check_range("initial_axial_speed_m_s", initial_axial_speed_m_s, -10.0, 10.0)
    )
    kernel_p = _kernel_parameters(p, omega0, w0, steady.twist_rad, surface)
    capacity = math.ceil(_RING_SPAN / _SPACING_FRACTION) + 16
    ring_phi = np.zeros(capacity)
    ring_r = np.zeros(capacity)
    # steady-drilling history: two samples of R(phi) = r phi, three blade angles apart
    ring_phi[0] = -3.0 * p.blade_angle_rad
    ring_r[0] = steady.surface_slope_m_rad * ring_phi[0]
    ring = np.array([0, 1, 0], dtype=np.int64)
    m = n_steps + 1
    out = [np.full(m, np.nan) for _ in range(7)]
    regime = np.zeros(m, dtype=np.int8)
    loss = np.zeros(m)
    stats = np.zeros(4)
    _simulate_kernel(  # type: ignore[call-arg]
        kernel_p, n_steps, h, om_start, v_start, ring_phi, ring_r, ring, *out, regime, loss, stats
    )
    done = int(stats[_S_DONE]) + 1
    u, v, phi, om, w, tq, dn = (a[:done] for a in out)
    regime = regime[:done]
    return CoupledTrace(
        time_s=np.arange(done, dtype=np.float64) * h,
        bit_speed_rad_s=om,
        axial_speed_m_s=v,
        depth_m=u,
        bit_angle_rad=phi,
        weight_on_bit_n=w,
        torque_on_bit_nm=tq,
        depth_of_cut_m=dn,
        regime=regime,
        stuck=regime >= _STUCK,
        off_bottom=(regime == _AIR) | (regime == _STUCK_AIR),
        axial_hold=regime == _HOLD,
        top_drive_speed_rad_s=omega0,
        applied_force_n=w0,
        steady=steady,
        parameters=p,
        step_s=h,
        surface=surface,
        switch_loss_j=loss[:done],
        switches=int(stats[_S_SWITCHES]),
        diverged=done < m,
    )


# ---------------------------------------------------------------------------------------------
# Features of a run
# ---------------------------------------------------------------------------------------------

STANDARD_POINTS: Final[dict[str, tuple[float, float]]] = {
    "P1": (60e3, 20.0),
    "P2": (60e3, 10.0),
    "P3": (60e3, 4.0),
    "P4": (90e3, 4.0),
}
"""Operating points of the standard run: name -> (applied force ``W_0``, N; top-drive speed
``Omega_0``, rad/s). P1: stable steady drilling; P2: torsional oscillation without stick;
P3: torsional stick-slip; P4: stick-slip with bit bounce."""
STANDARD_DURATION_S: Final = 400.0
"""Length of the standard run, s."""
STANDARD_WINDOW_S: Final = (100.0, 400.0)
"""Window of the standard run's features, s."""


@dataclass(frozen=True)
class RunFeatures:
    """Features of a run over a window ``[t1, t2]``.

    Attributes:
        om_amp_rel: ``(max Omega - min Omega) / (2 Omega_0)`` over the step ends, -.
        om_rms_dev_rad_s: RMS of ``Omega`` about its mean, ``sqrt(mean((Omega - Omega_0)^2) -
            (Omega_mean - Omega_0)^2)``, rad/s.
        frac_stick: Fraction of the window spent stuck, -.
        frac_bounce: Fraction of the window spent off the rock, -.
        frac_axhold: Fraction of the window spent rotating with ``V`` held at 0, -.
        frac_stick_backtorque: Fraction of the window spent stuck on the rock with a negative
            string torque (the rock holds the bit against backward rotation), -.
        rop_m_s: Rate of penetration ``(U(t2) - U(t1)) / (t2 - t1)``, m/s.
        rop_rel: ``rop_m_s / V_0``, -.
        om_mean_rad_s: Mean bit speed ``(Phi(t2) - Phi(t1)) / (t2 - t1)``, rad/s.
        period_s: Median interval between stick onsets if there are at least 3, else between
            upward crossings of ``Omega`` through its window mean; NaN without two, s.
        wob_min_n, wob_max_n, wob_mean_n: Weight on bit: least, greatest, time mean, N.
        tob_min_nm, tob_max_nm, tob_mean_nm: Torque on bit: least, greatest, time mean, N m.
    """

    om_amp_rel: float
    om_rms_dev_rad_s: float
    frac_stick: float
    frac_bounce: float
    frac_axhold: float
    frac_stick_backtorque: float
    rop_m_s: float
    rop_rel: float
    om_mean_rad_s: float
    period_s: float
    wob_min_n: float
    wob_max_n: float
    wob_mean_n: float
    tob_min_nm: float
    tob_max_nm: float
    tob_mean_nm: float


FEATURE_SYMBOLS: Final[dict[str, str]] = {
    "om_amp_rel": "Om_amp_rel",
    "om_rms_dev_rad_s": "Om_rms_dev",
    "frac_stick": "frac_stick",
    "frac_bounce": "frac_bounce",
    "frac_axhold": "frac_axhold",
    "frac_stick_backtorque": "frac_stick_backtorque",
    "rop_m_s": "ROP",
    "rop_rel": "ROP_rel",
    "om_mean_rad_s": "Om_mean",
    "period_s": "period",
    "wob_min_n": "WOB_min",
    "wob_max_n": "WOB_max",
    "wob_mean_n": "WOB_mean",
    "tob_min_nm": "TOB_min",
    "tob_max_nm": "TOB_max",
    "tob_mean_nm": "TOB_mean",
}
"""Field of :class:`RunFeatures` -> the feature's name in docs/coupled-model.md."""


def _median_interval(times: npt.NDArray[np.float64]) -> float:
    return float(np.median(np.diff(times))) if times.size >= 2 else math.nan


def run_features(
    trace: CoupledTrace, window_s: tuple[float, float] = STANDARD_WINDOW_S
) -> RunFeatures:
    """The features of ``trace`` over ``window_s`` (see :class:`RunFeatures`). The window is
    taken between the samples nearest its ends; time fractions and means count the samples
    after the first, each standing for one step.

    Raises:
        ValueError: when the window is not within the trace or holds fewer than two steps.
    """
    end = float(trace.time_s[-1])
    t1, t2 = check_interval("window_s", window_s, 0.0, end + 0.5 * trace.step_s)
    i1 = round(t1 / trace.step_s)
    i2 = min(round(t2 / trace.step_s), trace.time_s.size - 1)
    require("window_s", window_s, "a window of at least two steps", i2 - i1 >= 2)
    span = float(trace.time_s[i2] - trace.time_s[i1])
    omega0 = trace.top_drive_speed_rad_s
    om = trace.bit_speed_rad_s[i1 : i2 + 1]
    after = slice(i1 + 1, i2 + 1)
    om_mean = float(trace.bit_angle_rad[i2] - trace.bit_angle_rad[i1]) / span
    variance = float(np.mean((om - omega0) ** 2)) - (om_mean - omega0) ** 2
    rop = float(trace.depth_m[i2] - trace.depth_m[i1]) / span
    stuck = trace.stuck[i1 : i2 + 1]
    onsets = trace.time_s[i1 + 1 : i2 + 1][stuck[1:] & ~stuck[:-1]]
    if onsets.size >= 3:
        period = _median_interval(onsets)
    else:
        level = float(np.mean(om))
        below = om[:-1] < level
        up = np.flatnonzero(below & (om[1:] >= level))
        t = trace.time_s[i1 : i2 + 1]
        crossings = t[up] + (level - om[up]) / (om[up + 1] - om[up]) * (t[up + 1] - t[up])
        period = _median_interval(crossings)
    string = trace.string_torque_nm[after]
    back = trace.stuck[after] & ~trace.off_bottom[after] & (string < 0)
    wob = trace.weight_on_bit_n[i1 : i2 + 1]
    tob = trace.torque_on_bit_nm[i1 : i2 + 1]
    return RunFeatures(
        om_amp_rel=float(om.max() - om.min()) / (2 * omega0),
        om_rms_dev_rad_s=math.sqrt(max(variance, 0.0)),
        frac_stick=float(np.mean(trace.stuck[after])),
        frac_bounce=float(np.mean(trace.off_bottom[after])),
        frac_axhold=float(np.mean(trace.axial_hold[after])),
        frac_stick_backtorque=float(np.mean(back)),
        rop_m_s=rop,
        rop_rel=rop / trace.steady.rate_of_penetration_m_s,
        om_mean_rad_s=om_mean,
        period_s=period,
        wob_min_n=float(wob.min()),
        wob_max_n=float(wob.max()),
        wob_mean_n=float(np.mean(trace.weight_on_bit_n[after])),
        tob_min_nm=float(tob.min()),
        tob_max_nm=float(tob.max()),
        tob_mean_nm=float(np.mean(trace.torque_on_bit_nm[after])),
    )


def standard_run(
    parameters: str | RgdParameters,
    point: str,
    *,
    duration_s: float = STANDARD_DURATION_S,
    window_s: tuple[float, float] = STANDARD_WINDOW_S,
    step_s: float = 1e-4,
    surface: str = "max",
) -> tuple[CoupledTrace, RunFeatures]:
    """The standard run at the operating point ``point`` of :data:`STANDARD_POINTS`
    (initial condition "a": ``Omega(0) = 0.9 Omega_0``, ``V(0) = V_0``) and its features."""
    check_choice("point", point, STANDARD_POINTS, "operating point")
    force, speed = STANDARD_POINTS[point]
    trace = simulate(parameters, speed, force, duration_s, step_s=step_s, surface=surface)
    return trace, run_features(trace, window_s)


# ---------------------------------------------------------------------------------------------
# Linear stability of steady drilling
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Linearised:
    """The linearised delay equation ``x' = A0 x + A1 x(t - tau)``, ``x = (u, u', phi, phi')``,
    and the coefficients of ``Delta(s)``."""

    a0: npt.NDArray[np.float64]
    a1: npt.NDArray[np.float64]
    tau: float
    r: float
    p: RgdParameters


def _linearise(p: RgdParameters, omega0: float, w0: float) -> _Linearised:
    steady = steady_state(p, omega0, w0)
    r = steady.surface_slope_m_rad
    m, i = p.axial_mass_kg, p.inertia_kg_m2
    ka, kt = p.k_a, p.k_t
    a0 = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [-(p.axial_stiffness_n_m + ka) / m, -p.axial_damping_ns_m / m, ka * r / m, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [-kt / i, 0.0, (kt * r - p.torsional_stiffness_nm_rad) / i, -p.torsional_damping_nms_rad / i],
        ]
    )  # fmt: skip
    a1 = np.array(
        [
            [0.0, 0.0, 0.0, 0.0],
            [ka / m, 0.0, -ka * r / m, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [kt / i, 0.0, -kt * r / i, 0.0],
        ]
    )
    return _Linearised(a0, a1, steady.delay_s, r, p)


def _delta(lin: _Linearised, s: complex) -> tuple[complex, complex]:
    """``Delta(s)`` of (6.1) and its derivative ``Delta'(s)``."""
    p = lin.p
    m, c_a, k = p.axial_mass_kg, p.axial_damping_ns_m, p.axial_stiffness_n_m
    i, c_t, c = p.inertia_kg_m2, p.torsional_damping_nms_rad, p.torsional_stiffness_nm_rad
    pa, dpa = m * s * s + c_a * s + k, 2 * m * s + c_a
    pt, dpt = i * s * s + c_t * s + c, 2 * i * s + c_t
    decay = cmath.exp(-s * lin.tau)
    e, de = 1 - decay, lin.tau * decay
    mix = p.k_a * pt - p.k_t * lin.r * pa
    dmix = p.k_a * dpt - p.k_t * lin.r * dpa
    return pa * pt + e * mix, dpa * pt + pa * dpt + de * mix + e * dmix


def _chebyshev(n: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Chebyshev points ``x_j = cos(j pi / n)`` (n + 1,) and the differentiation matrix."""
    x = np.cos(np.pi * np.arange(n + 1) / n)
    c = np.ones(n + 1)
    c[0] = c[-1] = 2.0
    c *= (-1.0) ** np.arange(n + 1)
    dx = x[:, None] - x[None, :] + np.eye(n + 1)
    d = np.outer(c, 1.0 / c) / dx
    d -= np.diag(d.sum(axis=1))
    return x, d


def _newton(lin: _Linearised, s: complex, scale: float) -> complex | None:
    for _ in range(50):
        value, slope = _delta(lin, s)
        if slope == 0:
            return None
        step = value / slope
        s -= step
        if abs(step) <= 1e-12 * max(1.0, abs(s)):
            break
    value, _ = _delta(lin, s)
    return s if abs(value) <= 1e-8 * scale * max(1.0, abs(s)) ** 4 else None


def rightmost_roots(
    parameters: str | RgdParameters,
    top_drive_speed_rad_s: float,
    applied_force_n: float,
    *,
    count: int = 6,
    nodes: int | None = None,
) -> npt.NDArray[np.complex128]:
    """The rightmost roots of the characteristic equation (6.1) of steady drilling,
    ``Delta(s) = P_a P_t + (1 - exp(-s tau)) (k_a P_t - k_t r P_a) = 0``, with
    ``P_a = M s^2 + c_a s + K`` and ``P_t = I s^2 + c_t s + C``.

    The roots come from the eigenvalues of the Chebyshev collocation of the delay equation's
    infinitesimal generator, each refined by Newton's method on ``Delta``; the trivial root
    ``s = 0`` (rigid axial translation when ``K = 0``) is left out. One root of each complex
    pair is given (``Im s >= 0``).

    Args:
        parameters: A preset name or an :class:`RgdParameters`.
        top_drive_speed_rad_s: ``Omega_0``, rad/s.
        applied_force_n: ``W_0`` above ``W_f_bar``, N.
        count: How many roots, at least 1.
        nodes: Collocation nodes (default: enough for the axial mode over the delay, 30-160).

    Returns:
        Roots ``s`` (count,), 1/s, by decreasing real part.
    """
    p = _resolve(parameters)
    omega0, w0 = _check_operating_point(p, top_drive_speed_rad_s, applied_force_n)
    check_int("count", count, 1)
    lin = _linearise(p, omega0, w0)
    fastest = math.sqrt(2 * p.k_a / p.axial_mass_kg) + math.sqrt(
        p.torsional_stiffness_nm_rad / p.inertia_kg_m2
    )
    if nodes is None:
        nodes = int(min(160, max(30, 20 + 2.0 * lin.tau * fastest)))
    check_int("nodes", nodes, 4)
    x, d = _chebyshev(nodes)
    dim = 4
    size = dim * (nodes + 1)
    generator = np.kron(d * (2.0 / lin.tau), np.eye(dim))  # theta = tau (x - 1) / 2
    generator[:dim, :] = 0.0
    generator[:dim, :dim] = lin.a0
    generator[:dim, size - dim :] = lin.a1
    eigenvalues = np.linalg.eigvals(generator)
    eigenvalues = eigenvalues[np.isfinite(eigenvalues) & (eigenvalues.imag >= -1e-9)]
    eigenvalues = eigenvalues[np.argsort(-eigenvalues.real)]
    scale = p.axial_mass_kg * p.inertia_kg_m2
    trivial = 1e-7 * fastest
    roots: list[complex] = []
    for guess in eigenvalues[: 4 * count + 8]:
        root = _newton(lin, complex(guess), scale)
        if root is None:
            continue
        if root.imag < 0:
            root = root.conjugate()
        if abs(root) < trivial:
            continue
        if any(abs(root - known) <= 1e-7 * max(1.0, abs(root)) for known in roots):
            continue
        roots.append(root)
    roots.sort(key=lambda s: -s.real)
    return np.array(roots[:count], dtype=np.complex128)


def spectral_abscissa(
    parameters: str | RgdParameters,
    top_drive_speed_rad_s: float,
    applied_force_n: float,
    *,
    nodes: int | None = None,
) -> float:
    """Largest real part of the non-trivial roots of (6.1), 1/s: steady drilling is stable
    iff it is negative."""
    roots = rightmost_roots(
        parameters, top_drive_speed_rad_s, applied_force_n, count=1, nodes=nodes
    )
    return float(roots[0].real)


def stability_map(
    parameters: str | RgdParameters,
    applied_forces_n: Sequence[float],
    top_drive_speeds_rad_s: Sequence[float],
) -> npt.NDArray[np.float64]:
    """Spectral abscissa of steady drilling over a grid, (forces, speeds), 1/s (negative:
    stable)."""
    p = _resolve(parameters)
    return np.array(
        [[spectral_abscissa(p, s, f) for s in top_drive_speeds_rad_s] for f in applied_forces_n]
    )


def stable_speed_intervals(
    parameters: str | RgdParameters,
    applied_force_n: float,
    *,
    speed_range_rad_s: tuple[float, float] = (1.0, 60.0),
    grid: int = 60,
    tolerance_rad_s: float = 1e-6,
) -> list[tuple[float, float]]:
    """Top-drive speeds at which steady drilling is stable, as intervals of
    ``speed_range_rad_s``: the spectral abscissa on a geometric grid of ``grid`` speeds, each
    sign change refined by regula falsi to ``tolerance_rad_s``.

    Returns:
        ``[(low, high), ...]`` in rad/s; an end that is an end of the range is not a
        crossing.
    """
    p = _resolve(parameters)
    low, high = check_interval("speed_range_rad_s", speed_range_rad_s, 1e-3, 1e3)
    require("speed_range_rad_s", speed_range_rad_s, "low < high", low < high)
    check_int("grid", grid, 3)
    speeds = np.geomspace(low, high, grid)
    alpha = [spectral_abscissa(p, s, applied_force_n) for s in speeds]

    def crossing(a: float, fa: float, b: float, fb: float) -> float:
        side = 0
        while b - a > tolerance_rad_s:
            c = b - fb * (b - a) / (fb - fa)
            if not (a < c < b):
                c = 0.5 * (a + b)
            fc = spectral_abscissa(p, c, applied_force_n)
            if (fc < 0) == (fa < 0):
                a, fa = c, fc
                if side == 1:
                    fb *= 0.5
                side = 1
            else:
                b, fb = c, fc
                if side == -1:
                    fa *= 0.5
                side = -1
        return 0.5 * (a + b)

    intervals: list[tuple[float, float]] = []
    start = low if alpha[0] < 0 else None
    for k in range(1, grid):
        a, b, fa, fb = speeds[k - 1], speeds[k], alpha[k - 1], alpha[k]
        if (fa < 0) == (fb < 0):
            continue
        at = crossing(float(a), fa, float(b), fb)
        if fb < 0:
            start = at
        else:
            assert start is not None
            intervals.append((start, at))
            start = None
    if start is not None:
        intervals.append((start, high))
    return intervals


def critical_speed_rad_s(
    parameters: str | RgdParameters,
    applied_force_n: float,
    *,
    speed_range_rad_s: tuple[float, float] = (1.0, 60.0),
    grid: int = 60,
) -> float:
    """The top-drive speed above which steady drilling is stable: the lower end of the first
    stable interval of :func:`stable_speed_intervals` in ``speed_range_rad_s`` (scanned on
    ``grid`` speeds), rad/s.

    Raises:
        ValueError: when no speed of the range is stable (pure RGD, ``c_t = 0``, has none) or
            steady drilling is already stable at the lowest speed of the range.
    """
    p = _resolve(parameters)
    intervals = stable_speed_intervals(
        p, applied_force_n, speed_range_rad_s=speed_range_rad_s, grid=grid
    )
    low, high = speed_range_rad_s
    if not intervals:
        raise ValueError(
            f"steady drilling at applied_force_n = {shown(applied_force_n)} is unstable at every "
            f"top-drive speed in [{low:g}, {high:g}] rad/s: no critical speed (with "
            f"torsional_damping_nms_rad = {p.torsional_damping_nms_rad:g}; pure RGD, 0, is "
            "unstable everywhere)"
        )
    if intervals[0][0] <= low:
        raise ValueError(
            f"steady drilling at applied_force_n = {shown(applied_force_n)} is already stable at "
            f"the lowest speed {low:g} rad/s of speed_range_rad_s: lower it"
        )
    return intervals[0][0]


def simulated_map(
    parameters: str | RgdParameters,
    applied_forces_n: Sequence[float],
    top_drive_speeds_rad_s: Sequence[float],
    *,
    duration_s: float = 100.0,
    window_s: tuple[float, float] = (50.0, 100.0),
    step_s: float = 1e-4,
    surface: str = "max",
) -> dict[str, npt.NDArray[np.float64]]:
    """Stick-slip and bounce over a grid from simulations started as the standard run.

    Returns:
        ``{"frac_stick", "frac_bounce", "om_amp_rel"}``, each (forces, speeds), the features
        of :class:`RunFeatures` over ``window_s``.
    """
    p = _resolve(parameters)
    shape = (len(applied_forces_n), len(top_drive_speeds_rad_s))
    names = ("frac_stick", "frac_bounce", "om_amp_rel")
    result = {name: np.zeros(shape) for name in names}
    for i, force in enumerate(applied_forces_n):
        for j, speed in enumerate(top_drive_speeds_rad_s):
            trace = simulate(p, speed, force, duration_s, step_s=step_s, surface=surface)
            features = run_features(trace, window_s)
            for name in names:
                result[name][i, j] = getattr(features, name)
    return result
