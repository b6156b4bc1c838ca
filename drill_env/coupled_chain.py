"""The field string with axial elements and the regenerative (RGD) bit (docs/field-coupled.md).

Axial discretisation. The same sections and the same elements as the torsional chain of
:func:`drill_env.distributed.discretize` (``section_element_counts``): element ``e`` of length
``l`` in a section of cross-section ``A = pi (OD^2 - ID^2) / 4`` is an axial spring
``E A / l`` (N/m) and carries the mass ``rho A l`` (kg), half at each end node; the lumped-mass
model of the bar equation ``rho A u_tt = (E A u_x)_x``. Young's modulus is ``2 G (1 + nu)``
with ``nu = 0.3`` unless given per section (:class:`AxialProperties`). Damping has the forms of
the torsional chain: mud drag ``k_a rho A v`` per metre, lumped like the mass, with the
torsional mud rate by default (the coupled model of Aarsnes & Aamo sets its axial and
torsional damping coefficients equal), and a Kelvin-Voigt damper ``tau E A / l`` in every
element with the torsional material time constant ``tau``.

Boundaries. Torsion: the top node is the top drive, driven by a torque or held at a speed.
Axially the top node is either pushed by a constant applied force ``W_0`` (the submerged weight
less the hook load, gathered at the top: the weight's distribution only shifts the static
strain of the linear elements), or tied by the derrick/hook stiffness ``K_h`` to a hook
lowered at ``V_top`` (``K_h = inf``: the top node moves with the hook), with the spring
preloaded to ``W_0`` at the start. The bottom node carries the bit: the RGD law and regime rules
of :mod:`drill_env.coupled` (``bit_load``, ``switching_functions``, ``stop_rule``,
``switch_rule``, the rock surface stored against the bit angle; one home), with the bottom
node's mass and inertia in place of the lumped ``M`` and ``I``.

State (:func:`state_size`, ``n`` nodes): torsional chain ``(w_0, theta_0, ..., w_{n-1})``
(rad/s, rad), axial chain ``(v_0, s_0, ..., v_{n-1})`` (m/s, m; ``s_e = u_e - u_{e+1}``, the
compression of element ``e``), the hook spring's compression (m), the bit depth ``U`` (m) and
angle ``Phi`` (rad), then three energy integrals (J): work done on the string at the top,
energy dissipated by the dampers, work done by the bit on the rock.

Integration as the lumped model's: fixed-step RK4 with the bit regime frozen in each step, every
regime switch located inside the step by regula falsi to ``1e-13`` of the step.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
import numpy.typing as npt
from numba import njit, prange

from drill_env.chain import CP_N, chain_probe_state, chain_surface_torque
from drill_env.coupled import (
    _AIR,
    _DOWN,
    _HOLD,
    _N_P,
    _P_BLADE,
    _P_SPACING,
    _RING_SPAN,
    _SPACING_FRACTION,
    _STUCK,
    _STUCK_AIR,
    _UP,
    SURFACE_RULES,
    RgdParameters,
    SteadyState,
    _from_rest,
    _kernel_parameters,
    _resolve,
    _surface,
    bit_load,
    illinois_update,
    steady_state,
    stop_rule,
    switch_rule,
    switching_functions,
)
from drill_env.coupled import (
    _record as _record_surface,
)
from drill_env.distributed import (
    Chain,
    DistributedStringParameters,
    discretize,
    resolve_distributed_parameters,
    section_element_counts,
)
from drill_env.friction import STUCK
from drill_env.kernel import (
    _base_torque,
    _check_noise_room,
    _command_and_torque,
    _finish,
    _record,
    _sense,
    _slot,
    _sums,
    residual_base,
)
from drill_env.layout import (
    CH_ACTUATOR,
    CH_HOLD,
    CH_TELEMETRY,
    F_BASE_TORQUE,
    F_COMMAND,
    F_LAST_COMMAND,
    F_LAST_TORQUE,
    F_NOISE_STD,
    F_TELEMETRY_NOISE_STD,
    F_TORQUE_NOISE_STD,
    I_MODE,
    I_NOISE_POS,
    I_REF_KNOTS,
    I_STATUS,
    I_STEP,
    I_WOB_KNOTS,
    N_CHANNEL,
    N_RECORD,
    PROF_REF_T,
    PROF_REF_V,
    PROF_WOB_T,
    PROF_WOB_V,
    REP_BASE_TORQUE,
    REP_WOB,
    SRC_STATE,
    STATUS_DIVERGED,
    STATUS_OK,
    X_BIT_SPEED,
)
from drill_env.limits import MAX_SPEED_RAD_S, MAX_TWIST_RAD
from drill_env.rewards import tracking_error
from drill_env.scenarios import profile_value
from drill_env.validation import check_choice, check_range, check_real, require, shown

__all__ = [
    "AXIAL_TOPS",
    "AxialChain",
    "AxialProperties",
    "CoupledChain",
    "FieldCoupledTrace",
    "axial_wave_speed_m_s",
    "coupled_chain",
    "discretize_axial",
    "simulate_field",
    "state_size",
]

FloatArray = npt.NDArray[np.float64]

DEFAULT_POISSON_RATIO: Final = 0.3
"""Poisson's ratio of steel: ``E = 2 G (1 + nu)`` (200 GPa with the 77 GPa of RGD-A)."""


# ---------------------------------------------------------------------------------------------
# Axial discretisation
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AxialProperties:
    """Axial properties of a distributed string beyond its torsional ones.

    Attributes:
        poisson_ratio: ``nu`` in ``E = 2 G (1 + nu)`` for sections without their own modulus, -.
        youngs_moduli_pa: Young's modulus of each section (top down), Pa; ``None``: from
            ``poisson_ratio``.
        mud_rate_per_s: Axial mud damping rate ``k_a``, 1/s (drag ``k_a rho A v`` per metre);
            ``None``: the torsional ``mud_rate_per_s`` of the string's damping.
        top_damping_ns_m: Viscous damping of the top node to ground, N s/m.
        bit_damping_ns_m: Viscous damping of the bottom node to ground, N s/m.
    """

    poisson_ratio: float = DEFAULT_POISSON_RATIO
    youngs_moduli_pa: tuple[float, ...] | None = None
    mud_rate_per_s: float | None = None
    top_damping_ns_m: float = 0.0
    bit_damping_ns_m: float = 0.0

    def __post_init__(self) -> None:
        nu = check_range("poisson_ratio", self.poisson_ratio, -0.99, 0.5)
        object.__setattr__(self, "poisson_ratio", nu)
        if self.youngs_moduli_pa is not None:
            moduli = tuple(check_real("youngs_moduli_pa", e) for e in self.youngs_moduli_pa)
            for e in moduli:
                require("youngs_moduli_pa", e, "positive finite moduli, Pa", 0 < e < math.inf)
            object.__setattr__(self, "youngs_moduli_pa", moduli)
        if self.mud_rate_per_s is not None:
            check_range("mud_rate_per_s", self.mud_rate_per_s, 0.0, 1e3)
        check_range("top_damping_ns_m", self.top_damping_ns_m, 0.0, 1e9)
        check_range("bit_damping_ns_m", self.bit_damping_ns_m, 0.0, 1e9)

    def moduli(self, string: DistributedStringParameters) -> tuple[float, ...]:
        """Young's modulus of each section of ``string``, Pa."""
        if self.youngs_moduli_pa is None:
            return tuple(
                2.0 * s.shear_modulus_pa * (1.0 + self.poisson_ratio) for s in string.sections
            )
        require(
            "youngs_moduli_pa", self.youngs_moduli_pa,
            f"one modulus per section ({len(string.sections)})",
            len(self.youngs_moduli_pa) == len(string.sections),
        )  # fmt: skip
        return self.youngs_moduli_pa


@dataclass(frozen=True, eq=False)
class AxialChain:
    """The axial lumped-mass chain: ``n`` node masses and ``n - 1`` elements (arrays float64).

    Attributes:
        node_mass_kg: Mass of each node, kg, (n,).
        node_damping_ns_m: Viscous damping of each node to ground, N s/m, (n,).
        element_stiffness_n_m: Spring of each element, N/m, (n - 1,).
        element_damping_ns_m: Damper in parallel with each spring, N s/m, (n - 1,).
    """

    node_mass_kg: FloatArray
    node_damping_ns_m: FloatArray
    element_stiffness_n_m: FloatArray
    element_damping_ns_m: FloatArray

    def __post_init__(self) -> None:
        n = len(self.node_mass_kg)
        require("number of nodes", n, ">= 2", n >= 2)
        for name, size in (
            ("node_mass_kg", n), ("node_damping_ns_m", n),
            ("element_stiffness_n_m", n - 1), ("element_damping_ns_m", n - 1),
        ):  # fmt: skip
            array = np.array(getattr(self, name), dtype=np.float64)
            if array.shape != (size,) or not np.all(np.isfinite(array)):
                raise ValueError(f"{name} must be finite with shape ({size},), got {shown(array)}")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        require("min node_mass_kg", float(self.node_mass_kg.min()), "> 0",
                bool(self.node_mass_kg.min() > 0))  # fmt: skip
        require("min element_stiffness_n_m", float(self.element_stiffness_n_m.min()), "> 0",
                bool(self.element_stiffness_n_m.min() > 0))  # fmt: skip
        for name in ("node_damping_ns_m", "element_damping_ns_m"):
            low = float(getattr(self, name).min())
            require(f"min {name}", low, ">= 0", low >= 0)

    @property
    def n_nodes(self) -> int:
        """Number of nodes ``n``."""
        return int(self.node_mass_kg.shape[0])


def axial_wave_speed_m_s(youngs_modulus_pa: float, density_kg_m3: float) -> float:
    """Axial (bar) wave speed ``sqrt(E / rho)``, m/s."""
    return math.sqrt(youngs_modulus_pa / density_kg_m3)


def discretize_axial(
    parameters: str | DistributedStringParameters, axial: AxialProperties | None = None
) -> AxialChain:
    """The axial chain of a distributed string, on the elements of its torsional chain (module
    docstring)."""
    p = resolve_distributed_parameters(parameters)
    axial = AxialProperties() if axial is None else axial
    moduli = axial.moduli(p)
    rate = p.damping.mud_rate_per_s if axial.mud_rate_per_s is None else axial.mud_rate_per_s
    counts = section_element_counts(p)
    n_elements = sum(counts)
    mass = np.zeros(n_elements + 1)
    mud = np.zeros(n_elements + 1)
    stiffness = np.empty(n_elements)
    e = 0
    for section, modulus, count in zip(p.sections, moduli, counts, strict=True):
        length = section.length_m / count
        area = math.pi * (section.outer_diameter_m**2 - section.inner_diameter_m**2) / 4.0
        element_mass = section.density_kg_m3 * area * length
        for _ in range(count):
            stiffness[e] = modulus * area / length
            mass[e] += 0.5 * element_mass
            mass[e + 1] += 0.5 * element_mass
            mud[e] += 0.5 * rate * element_mass
            mud[e + 1] += 0.5 * rate * element_mass
            e += 1
    mud[0] += axial.top_damping_ns_m
    mud[-1] += axial.bit_damping_ns_m
    return AxialChain(
        node_mass_kg=mass,
        node_damping_ns_m=mud,
        element_stiffness_n_m=stiffness,
        element_damping_ns_m=p.damping.material_time_constant_s * stiffness,
    )


@dataclass(frozen=True, eq=False)
class CoupledChain:
    """A torsional and an axial chain on the same nodes, the bit at the last one."""

    torsion: Chain
    axial: AxialChain

    def __post_init__(self) -> None:
        if not isinstance(self.torsion, Chain) or not isinstance(self.axial, AxialChain):
            raise TypeError("CoupledChain takes a Chain and an AxialChain")
        require(
            "axial nodes", self.axial.n_nodes, f"the torsional chain's {self.torsion.n_nodes}",
            self.axial.n_nodes == self.torsion.n_nodes,
        )  # fmt: skip

    @property
    def n_nodes(self) -> int:
        """Number of nodes ``n``."""
        return self.torsion.n_nodes


def coupled_chain(
    parameters: str | DistributedStringParameters | CoupledChain,
    axial: AxialProperties | None = None,
) -> CoupledChain:
    """Both chains of a distributed string (a :class:`CoupledChain` is returned as it is)."""
    if isinstance(parameters, CoupledChain):
        return parameters
    p = resolve_distributed_parameters(parameters)
    return CoupledChain(discretize(p), discretize_axial(p, axial))


def state_size(n_nodes: int) -> int:
    """Length of the coupled state of ``n_nodes`` nodes: ``4 n + 4``."""
    return 4 * n_nodes + 4


# ---------------------------------------------------------------------------------------------
# Compiled dynamics
# ---------------------------------------------------------------------------------------------

AXIAL_TOPS: Final = ("force", "hook")
"""Axial top boundaries: a constant applied force, or a hook lowered at a set speed through
the derrick/hook stiffness."""

# Header of the chain part of the parameter vector (after the bit's _N_P entries).
_Q_N = _N_P  # number of nodes
_Q_TOP_SPEED_HELD = _N_P + 1  # 1: the top drive's speed is held (kinematic), 0: torque driven
_Q_TOP_TORQUE = _N_P + 2  # top-drive torque when driven, N m
_Q_AXIAL_TOP = _N_P + 3  # 0 force, 1 hook spring, 2 top node moving with the hook
_Q_FORCE = _N_P + 4  # applied force at the top (force mode), N
_Q_HOOK_K = _N_P + 5  # derrick/hook stiffness, N/m
_Q_HOOK_V = _N_P + 6  # hook speed (down positive), m/s
_Q_ARRAYS = _N_P + 7
_MODE_FORCE, _MODE_SPRING, _MODE_RIGID = 0, 1, 2


def _parameter_length(n: int) -> int:
    return _Q_ARRAYS + 8 * n - 4


@njit(cache=True, inline="always")
def _offsets(n: int) -> tuple[int, int, int, int, int, int, int, int]:
    """Starts of the per-node and per-element arrays: 1/J, d_t, k_t, c_t, 1/m, c_a, k_a, c_a."""
    o = _Q_ARRAYS
    return (
        o,
        o + n,
        o + 2 * n,
        o + 3 * n - 1,
        o + 4 * n - 2,
        o + 5 * n - 2,
        o + 6 * n - 2,
        (o + 7 * n - 3),
    )


@njit(cache=True)
def _bit_forces(
    regime: int, y: np.ndarray, q: np.ndarray, ring_phi: np.ndarray, ring_r: np.ndarray,
    ring: np.ndarray, v_bit: float,
) -> tuple[float, float, float, float, float]:  # fmt: skip
    """``(d_n, F_ax, T_s, W, T)`` at the bit node: depth of cut per blade (m), axial force of
    the string on the bit node less its ground damping at axial speed ``v_bit`` (N), torque of
    the lowest element (N m), weight and torque on bit (N, N m)."""
    n = int(q[_Q_N])
    o_ij, o_dt, o_kt, o_ct, o_im, o_ca, o_ka, o_cae = _offsets(n)
    a = 2 * n - 1
    e = n - 2
    ts = q[o_kt + e] * y[2 * e + 1] + q[o_ct + e] * (y[2 * e] - y[2 * e + 2])
    f_ax = q[o_ka + e] * y[a + 2 * e + 1] + q[o_cae + e] * (y[a + 2 * e] - v_bit)
    f_ax -= q[o_ca + n - 1] * v_bit
    u = y[4 * n - 1]
    dn = u - _surface(y[4 * n] - q[_P_BLADE], ring_phi, ring_r, ring)
    w, tq = bit_load(regime, dn, f_ax, ts, q)
    return dn, f_ax, ts, w, tq


@njit(cache=True)
def _rhs(
    regime: int, y: np.ndarray, dy: np.ndarray, q: np.ndarray, ring_phi: np.ndarray,
    ring_r: np.ndarray, ring: np.ndarray,
) -> None:  # fmt: skip
    """Write ``dy/dt`` of the coupled state ``y`` in the frozen bit regime into ``dy``."""
    n = int(q[_Q_N])
    o_ij, o_dt, o_kt, o_ct, o_im, o_ca, o_ka, o_cae = _offsets(n)
    a = 2 * n - 1
    power_in = 0.0
    dissipated = 0.0
    dn, f_ax, ts, w, tq = _bit_forces(regime, y, q, ring_phi, ring_r, ring, y[a + 2 * n - 2])
    # torsion
    w0 = y[0]
    tau_prev = q[_Q_TOP_TORQUE]
    if q[_Q_TOP_SPEED_HELD] > 0.5:
        tau0 = q[o_kt] * y[1] + q[o_ct] * (y[0] - y[2])
        tau_prev = tau0 + q[o_dt] * w0  # the torque that holds the speed
    power_in += tau_prev * w0
    for i in range(n - 1):
        wi = y[2 * i]
        dw = wi - y[2 * i + 2]
        tau = q[o_kt + i] * y[2 * i + 1] + q[o_ct + i] * dw
        dy[2 * i] = (tau_prev - tau - q[o_dt + i] * wi) * q[o_ij + i]
        dy[2 * i + 1] = dw
        dissipated += q[o_ct + i] * dw * dw + q[o_dt + i] * wi * wi
        tau_prev = tau
    if q[_Q_TOP_SPEED_HELD] > 0.5:
        dy[0] = 0.0
    # axial
    mode = int(q[_Q_AXIAL_TOP])
    v0 = y[a]
    if mode == _MODE_FORCE:
        f_prev = q[_Q_FORCE]
        power_in += f_prev * v0
    elif mode == _MODE_SPRING:
        f_prev = q[_Q_HOOK_K] * y[4 * n - 2]
        power_in += f_prev * q[_Q_HOOK_V]
    else:
        f0 = q[o_ka] * y[a + 1] + q[o_cae] * (y[a] - y[a + 2])
        f_prev = f0 + q[o_ca] * v0
        power_in += f_prev * v0
    for i in range(n - 1):
        vi = y[a + 2 * i]
        dv = vi - y[a + 2 * i + 2]
        f = q[o_ka + i] * y[a + 2 * i + 1] + q[o_cae + i] * dv
        dy[a + 2 * i] = (f_prev - f - q[o_ca + i] * vi) * q[o_im + i]
        dy[a + 2 * i + 1] = dv
        dissipated += q[o_cae + i] * dv * dv + q[o_ca + i] * vi * vi
        f_prev = f
    if mode == _MODE_RIGID:
        dy[a] = 0.0
    dy[4 * n - 2] = q[_Q_HOOK_V] - v0 if mode == _MODE_SPRING else 0.0
    # the bit node
    m = n - 1
    wb = y[2 * m]
    vb = y[a + 2 * m]
    dissipated += q[o_dt + m] * wb * wb + q[o_ca + m] * vb * vb
    if regime == _STUCK:
        dy[2 * m] = 0.0
        dy[a + 2 * m] = 0.0
        dy[4 * n - 1] = 0.0
        dy[4 * n] = 0.0
        bit_power = 0.0
    elif regime == _STUCK_AIR:
        dy[2 * m] = 0.0
        dy[a + 2 * m] = f_ax * q[o_im + m]
        dy[4 * n - 1] = vb
        dy[4 * n] = 0.0
        bit_power = 0.0
    else:
        dy[2 * m] = (ts - q[o_dt + m] * wb - tq) * q[o_ij + m]
        dy[4 * n] = wb
        if regime == _HOLD:
            dy[a + 2 * m] = 0.0
            dy[4 * n - 1] = 0.0
        else:
            dy[a + 2 * m] = (f_ax - w) * q[o_im + m]
            dy[4 * n - 1] = vb
        bit_power = w * dy[4 * n - 1] + tq * wb
    dy[4 * n + 1] = power_in
    dy[4 * n + 2] = dissipated
    dy[4 * n + 3] = bit_power


@njit(cache=True)
def _rk4(
    regime: int, y: np.ndarray, dt: float, out: np.ndarray, work: np.ndarray, q: np.ndarray,
    ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> None:  # fmt: skip
    """One RK4 step of ``dt`` (s) from ``y`` into ``out``; ``work`` is (5, size) scratch."""
    size = y.shape[0]
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    _rhs(regime, y, k1, q, ring_phi, ring_r, ring)
    hh = 0.5 * dt
    for i in range(size):
        tmp[i] = y[i] + hh * k1[i]
    _rhs(regime, tmp, k2, q, ring_phi, ring_r, ring)
    for i in range(size):
        tmp[i] = y[i] + hh * k2[i]
    _rhs(regime, tmp, k3, q, ring_phi, ring_r, ring)
    for i in range(size):
        tmp[i] = y[i] + dt * k3[i]
    _rhs(regime, tmp, k4, q, ring_phi, ring_r, ring)
    s = dt / 6.0
    for i in range(size):
        out[i] = y[i] + s * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def _events(
    g: np.ndarray, regime: int, y: np.ndarray, q: np.ndarray, ring_phi: np.ndarray,
    ring_r: np.ndarray, ring: np.ndarray,
) -> None:  # fmt: skip
    n = int(q[_Q_N])
    vb = y[4 * n - 3]
    dn, f_ax, ts, w, tq = _bit_forces(regime, y, q, ring_phi, ring_r, ring, vb)
    switching_functions(g, regime, dn, f_ax, ts, vb, y[2 * n - 2], q)


@njit(cache=True)
def _switch(
    regime: int, which: int, y: np.ndarray, q: np.ndarray, ring_phi: np.ndarray,
    ring_r: np.ndarray, ring: np.ndarray,
) -> tuple[int, float]:  # fmt: skip
    """Apply switch ``which`` to ``y`` in place; ``(new regime, kinetic energy removed, J)``."""
    n = int(q[_Q_N])
    dn, f_rest, ts, w, tq = _bit_forces(regime, y, q, ring_phi, ring_r, ring, 0.0)
    new, v, om, loss = switch_rule(regime, which, dn, f_rest, ts, y[4 * n - 3], y[2 * n - 2], q)
    y[4 * n - 3] = v
    y[2 * n - 2] = om
    return new, loss


@njit(cache=True)
def _locate(
    which: int, regime: int, y: np.ndarray, dt: float, g_start: float, g_end: float,
    tolerance: float, g: np.ndarray, trial: np.ndarray, work: np.ndarray, q: np.ndarray,
    ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> float:  # fmt: skip
    """Time (s) into the step at which switching function ``which`` turns negative along the
    RK4 solution, by regula falsi (Illinois); the returned end lies on the far side."""
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
        _rk4(regime, y, c, trial, work, q, ring_phi, ring_r, ring)
        _events(g, regime, trial, q, ring_phi, ring_r, ring)
        fc = g[which]
        if not (fc < 0.0 or fc > 0.0):
            return c
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
    return b


@njit(cache=True)
def initial_regime(
    y: np.ndarray, q: np.ndarray, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray
) -> int:
    """Regime of the state ``y`` (the bit's speeds set consistently in place)."""
    n = int(q[_Q_N])
    dn, f_rest, ts, w, tq = _bit_forces(_DOWN, y, q, ring_phi, ring_r, ring, 0.0)
    vb = y[4 * n - 3]
    if y[2 * n - 2] <= 0.0:
        regime, v, om, loss = stop_rule(dn, f_rest, ts, vb, 0.0, q)
        y[4 * n - 3] = v
        y[2 * n - 2] = om
        return regime
    if dn < 0.0:
        return _AIR
    if vb > 0.0:
        return _DOWN
    if vb < 0.0:
        return _UP
    return _from_rest(dn, f_rest, q)


_MAX_SWITCHES: Final = 32
_A_LOSS, _A_SWITCHES, _A_CROWDED = range(3)


@njit(cache=True)
def coupled_chain_step(
    y: np.ndarray, regime: int, h: float, q: np.ndarray, ring_phi: np.ndarray,
    ring_r: np.ndarray, ring: np.ndarray, work: np.ndarray, acc: np.ndarray,
) -> int:  # fmt: skip
    """Advance the coupled state ``y`` in place by one step of ``h`` (s) from the bit regime
    ``regime`` with every regime switch located inside the step; returns the new regime.

    ``work``: scratch (9, size); ``acc`` (3,): kinetic energy removed at switches (J), switches
    and steps that hit the switch limit, incremented."""
    g0 = work[5, :4]
    g1 = work[6, :4]
    gc = work[6, 4:8]
    trial = work[7]
    trial2 = work[8]
    rk = work[:5]
    size = y.shape[0]
    tolerance = 1e-13 * h
    t = 0.0
    switches = 0
    while True:
        dt = h - t
        if dt <= 0.0:
            break
        _events(g0, regime, y, q, ring_phi, ring_r, ring)
        live = switches < _MAX_SWITCHES
        if live:
            now = -1
            for i in range(4):
                if g0[i] < 0.0:
                    now = i
                    break
            if now >= 0:  # inconsistent at the start: switch at once
                regime, loss = _switch(regime, now, y, q, ring_phi, ring_r, ring)
                acc[_A_LOSS] += loss
                acc[_A_SWITCHES] += 1
                switches += 1
                continue
        else:
            acc[_A_CROWDED] += 1
        _rk4(regime, y, dt, trial, rk, q, ring_phi, ring_r, ring)
        _events(g1, regime, trial, q, ring_phi, ring_r, ring)
        first = -1
        when = dt
        if live:
            for i in range(4):
                if g0[i] > 0.0 and g1[i] < 0.0:
                    at = _locate(
                        i, regime, y, dt, g0[i], g1[i], tolerance, gc, trial2, rk, q,
                        ring_phi, ring_r, ring,
                    )  # fmt: skip
                    if first < 0 or at < when:
                        first = i
                        when = at
        n = int(q[_Q_N])
        if first < 0:
            late = -1
            if live:
                for i in range(4):
                    if g0[i] == 0.0 and g1[i] < 0.0:  # left the surface on the wrong side
                        late = i
                        break
            for i in range(size):
                y[i] = trial[i]
            _record_surface(y[4 * n], y[4 * n - 1], q, ring_phi, ring_r, ring)
            if late >= 0:
                regime, loss = _switch(regime, late, y, q, ring_phi, ring_r, ring)
                acc[_A_LOSS] += loss
                acc[_A_SWITCHES] += 1
            break
        _rk4(regime, y, when, trial, rk, q, ring_phi, ring_r, ring)
        for i in range(size):
            y[i] = trial[i]
        t = h if when >= dt else t + when
        _record_surface(y[4 * n], y[4 * n - 1], q, ring_phi, ring_r, ring)
        regime, loss = _switch(regime, first, y, q, ring_phi, ring_r, ring)
        acc[_A_LOSS] += loss
        acc[_A_SWITCHES] += 1
        switches += 1
    return regime


_R_U, _R_V, _R_PHI, _R_OM, _R_W, _R_T, _R_DN, _R_TOP_TORQUE, _R_STORED = range(9)
_R_IN, _R_DISS, _R_BIT, _R_LOSS = range(9, 13)
_N_R = 13


@njit(cache=True)
def stored_energy(y: np.ndarray, q: np.ndarray) -> float:
    """Kinetic and elastic energy of the coupled state ``y``, J."""
    n = int(q[_Q_N])
    o_ij, o_dt, o_kt, o_ct, o_im, o_ca, o_ka, o_cae = _offsets(n)
    a = 2 * n - 1
    energy = 0.0
    for i in range(n):
        energy += 0.5 * y[2 * i] ** 2 / q[o_ij + i] + 0.5 * y[a + 2 * i] ** 2 / q[o_im + i]
    for e in range(n - 1):
        energy += 0.5 * q[o_kt + e] * y[2 * e + 1] ** 2 + 0.5 * q[o_ka + e] * y[a + 2 * e + 1] ** 2
    if int(q[_Q_AXIAL_TOP]) == _MODE_SPRING:
        energy += 0.5 * q[_Q_HOOK_K] * y[4 * n - 2] ** 2
    return energy


@njit(cache=True)
def _simulate_kernel(
    y: np.ndarray, q: np.ndarray, n_steps: int, h: float, ring_phi: np.ndarray,
    ring_r: np.ndarray, ring: np.ndarray, out: np.ndarray, out_regime: np.ndarray,
    acc: np.ndarray,
) -> int:  # fmt: skip
    """Run ``n_steps`` steps of ``h`` (s); row ``k`` of ``out`` (``_R_*`` columns) is the state
    after ``k`` steps. Returns the steps completed (fewer when the state stopped being
    finite)."""
    n = int(q[_Q_N])
    size = y.shape[0]
    work = np.zeros((9, max(size, 8)))
    regime = initial_regime(y, q, ring_phi, ring_r, ring)
    for k in range(n_steps + 1):
        if k > 0:
            regime = coupled_chain_step(y, regime, h, q, ring_phi, ring_r, ring, work, acc)
            for i in range(size):
                if not math.isfinite(y[i]):
                    return k - 1
        vb = y[4 * n - 3]
        dn, f_ax, ts, w, tq = _bit_forces(regime, y, q, ring_phi, ring_r, ring, vb)
        row = out[k]
        row[_R_U] = y[4 * n - 1]
        row[_R_V] = vb
        row[_R_PHI] = y[4 * n]
        row[_R_OM] = y[2 * n - 2]
        row[_R_W] = w
        row[_R_T] = tq
        row[_R_DN] = dn
        row[_R_STORED] = stored_energy(y, q)
        row[_R_IN] = y[4 * n + 1]
        row[_R_DISS] = y[4 * n + 2]
        row[_R_BIT] = y[4 * n + 3]
        row[_R_LOSS] = acc[_A_LOSS]
        o_kt = _Q_ARRAYS + 2 * n
        row[_R_TOP_TORQUE] = q[o_kt] * y[1]
        out_regime[k] = regime
    return n_steps


# ---------------------------------------------------------------------------------------------
# Python side
# ---------------------------------------------------------------------------------------------


def _check_top(
    axial_top: str, hook_speed_m_s: float | None, hook_stiffness_n_m: float
) -> tuple[int, float, float]:
    check_choice("axial_top", axial_top, AXIAL_TOPS, "axial top boundary")
    if axial_top == "force":
        require(
            "hook_speed_m_s", hook_speed_m_s, "None with axial_top='force'", hook_speed_m_s is None
        )
        return _MODE_FORCE, 0.0, 0.0
    require(
        "hook_speed_m_s",
        hook_speed_m_s,
        "a speed with axial_top='hook'",
        hook_speed_m_s is not None,
    )
    speed = check_range("hook_speed_m_s", hook_speed_m_s, -1.0, 1.0)
    stiffness = check_real("hook_stiffness_n_m", hook_stiffness_n_m)
    require("hook_stiffness_n_m", hook_stiffness_n_m, "> 0 (inf: rigid)", stiffness > 0)
    return (_MODE_RIGID if math.isinf(stiffness) else _MODE_SPRING), speed, stiffness


def parameter_vector(
    chain: CoupledChain,
    bit: RgdParameters,
    *,
    axial_top: str = "force",
    applied_force_n: float = 0.0,
    hook_speed_m_s: float | None = None,
    hook_stiffness_n_m: float = math.inf,
    top_speed_held: bool = True,
    top_drive_torque_nm: float = 0.0,
    surface: str = "max",
) -> FloatArray:
    """The flat parameter vector of the compiled coupled chain: the bit's entries (the lumped
    kernel's layout of :mod:`drill_env.coupled`, with the bottom node's mass, inertia and ground
    damping), the boundary settings, then ``1/J, d_t, k_t, c_t, 1/m, c_a, k_a, c_a`` of the
    nodes and elements."""
    n = chain.n_nodes
    tor, ax = chain.torsion, chain.axial
    mode, speed, stiffness = _check_top(axial_top, hook_speed_m_s, hook_stiffness_n_m)
    lumped = dataclasses.replace(
        bit,
        axial_mass_kg=float(ax.node_mass_kg[-1]),
        inertia_kg_m2=float(tor.node_inertia_kg_m2[-1]),
        torsional_damping_nms_rad=float(tor.node_damping_nm_s_rad[-1]),
        axial_damping_ns_m=float(ax.node_damping_ns_m[-1]),
        axial_stiffness_n_m=0.0,
    )
    q = np.zeros(_parameter_length(n))
    q[:_N_P] = _kernel_parameters(lumped, 0.0, 0.0, 0.0, surface)
    q[_Q_N] = n
    q[_Q_TOP_SPEED_HELD] = 1.0 if top_speed_held else 0.0
    q[_Q_TOP_TORQUE] = top_drive_torque_nm
    q[_Q_AXIAL_TOP] = mode
    q[_Q_FORCE] = applied_force_n if mode == _MODE_FORCE else 0.0
    q[_Q_HOOK_K] = stiffness if mode == _MODE_SPRING else 0.0
    q[_Q_HOOK_V] = speed
    o = _Q_ARRAYS
    for values in (
        1.0 / tor.node_inertia_kg_m2, tor.node_damping_nm_s_rad, tor.element_stiffness_nm_rad,
        tor.element_damping_nm_s_rad, 1.0 / ax.node_mass_kg, ax.node_damping_ns_m,
        ax.element_stiffness_n_m, ax.element_damping_ns_m,
    ):  # fmt: skip
        q[o : o + values.shape[0]] = values
        o += values.shape[0]
    assert o == q.shape[0]
    return q


def chain_steady_state(
    chain: CoupledChain, bit: RgdParameters, top_drive_speed_rad_s: float, applied_force_n: float
) -> SteadyState:
    """Steady drilling of the chain: the lumped closed form with the ground damping of every
    node (all nodes turn at ``Omega_0`` and move at ``V_0``); ``twist_rad`` is the lowest
    element's."""
    lumped = dataclasses.replace(
        bit,
        torsional_damping_nms_rad=float(chain.torsion.node_damping_nm_s_rad[-1]),
        axial_damping_ns_m=float(chain.axial.node_damping_ns_m.sum()),
        torsional_stiffness_nm_rad=float(chain.torsion.element_stiffness_nm_rad[-1]),
        axial_stiffness_n_m=0.0,
    )
    return steady_state(lumped, top_drive_speed_rad_s, applied_force_n)


def steady_chain_state(
    chain: CoupledChain, steady: SteadyState, top_drive_speed_rad_s: float
) -> FloatArray:
    """The coupled state (energy integrals 0) of steady drilling: every node at ``Omega_0``
    and ``V_0``, each element carrying the torque and force of the bit and of the ground
    damping below it."""
    n = chain.n_nodes
    tor, ax = chain.torsion, chain.axial
    y = np.zeros(state_size(n))
    omega0, v0 = top_drive_speed_rad_s, steady.rate_of_penetration_m_s
    torque = steady.torque_on_bit_nm
    force = steady.weight_on_bit_n
    a = 2 * n - 1
    y[0 : 2 * n - 1 : 2] = omega0
    y[a : a + 2 * n - 1 : 2] = v0
    for e in range(n - 2, -1, -1):
        torque += tor.node_damping_nm_s_rad[e + 1] * omega0
        force += ax.node_damping_ns_m[e + 1] * v0
        y[2 * e + 1] = torque / tor.element_stiffness_nm_rad[e]
        y[a + 2 * e + 1] = force / ax.element_stiffness_n_m[e]
    return y


@dataclass(frozen=True)
class FieldCoupledTrace:
    """One run of :func:`simulate_field`, sampled at ``t = 0`` and every step end (m samples).

    Attributes:
        time_s: Sample times, (m,), s.
        bit_speed_rad_s, axial_speed_m_s: Bit node speeds, (m,), rad/s and m/s (down positive).
        depth_m, bit_angle_rad: Bit depth from its start and bit angle, (m,), m and rad.
        weight_on_bit_n, torque_on_bit_nm: Weight and torque on bit, (m,), N and N m.
        depth_of_cut_m: Depth of cut per blade (negative off the rock), (m,), m.
        regime: Bit regime (an index of ``drill_env.coupled.REGIME_NAMES``), (m,), int8.
        top_torque_nm: Spring torque of the top element, (m,), N m.
        stored_energy_j: Kinetic and elastic energy of the string, (m,), J.
        work_in_j: Work done on the string at the top since the start, (m,), J.
        dissipated_j: Energy dissipated by the dampers since the start, (m,), J.
        bit_work_j: Work of the bit on the rock since the start, (m,), J.
        switch_loss_j: Kinetic energy removed by velocity resets at switches, (m,), J.
        steady: Steady drilling at the operating point (the history before ``t = 0``).
        step_s: Integration step, s.
        diverged: The state stopped being finite; the trace ends at the last finite sample.
    """

    time_s: FloatArray
    bit_speed_rad_s: FloatArray
    axial_speed_m_s: FloatArray
    depth_m: FloatArray
    bit_angle_rad: FloatArray
    weight_on_bit_n: FloatArray
    torque_on_bit_nm: FloatArray
    depth_of_cut_m: FloatArray
    regime: npt.NDArray[np.int8]
    top_torque_nm: FloatArray
    stored_energy_j: FloatArray
    work_in_j: FloatArray
    dissipated_j: FloatArray
    bit_work_j: FloatArray
    switch_loss_j: FloatArray
    steady: SteadyState
    step_s: float
    diverged: bool

    @property
    def stuck(self) -> npt.NDArray[np.bool_]:
        """The bit does not rotate, (m,)."""
        return self.regime >= _STUCK

    @property
    def off_bottom(self) -> npt.NDArray[np.bool_]:
        """The bit is off the rock, (m,)."""
        return (self.regime == _AIR) | (self.regime == _STUCK_AIR)


def new_surface_ring(bit: RgdParameters, surface_slope_m_rad: float) -> tuple[
    FloatArray, FloatArray, npt.NDArray[np.int64]
]:  # fmt: skip
    """The rock-surface ring of the lumped model holding the steady-drilling history
    ``R(phi) = r phi`` behind ``phi = 0``: ``(angles, depths, indices)``."""
    capacity = math.ceil(_RING_SPAN / _SPACING_FRACTION) + 16
    ring_phi = np.zeros(capacity)
    ring_r = np.zeros(capacity)
    ring_phi[0] = -3.0 * bit.blade_angle_rad
    ring_r[0] = surface_slope_m_rad * ring_phi[0]
    return ring_phi, ring_r, np.array([0, 1, 0], dtype=np.int64)


MAX_SAMPLES: Final = 5_000_000
"""Most samples one :func:`simulate_field` call records."""


def simulate_field(
    string: str | DistributedStringParameters | CoupledChain,
    top_drive_speed_rad_s: float,
    applied_force_n: float,
    duration_s: float,
    *,
    bit: str | RgdParameters = "rgd_a",
    axial: AxialProperties | None = None,
    axial_top: str = "force",
    hook_speed_m_s: float | None = None,
    hook_stiffness_n_m: float = math.inf,
    initial_bit_speed_rad_s: float | None = None,
    step_s: float = 1e-4,
    surface: str = "max",
) -> FieldCoupledTrace:
    """The lumped model's standard run on the coupled field string: steady drilling before
    ``t = 0`` (rock surface ``R(phi) = r phi``), then the top drive held at ``Omega_0`` and the
    axial top boundary held, the bit started at ``initial_bit_speed_rad_s``.

    Args:
        string: A distributed preset name or parameter set, or a :class:`CoupledChain`.
        top_drive_speed_rad_s: Top-drive speed ``Omega_0`` in (0, 1000], rad/s.
        applied_force_n: Applied force ``W_0`` above the wear-flat force, N: at the top node
            (``axial_top="force"``) or the hook line's preload (``"hook"``).
        duration_s: Simulated time, s.
        bit: RGD preset name or parameters (its string entries are not used).
        axial: Axial properties (when ``string`` is not a chain).
        axial_top: ``"force"`` or ``"hook"`` (:data:`AXIAL_TOPS`).
        hook_speed_m_s: Hook speed with ``axial_top="hook"``, m/s (down positive).
        hook_stiffness_n_m: Derrick/hook stiffness, N/m (``inf``: the top node moves with the
            hook).
        initial_bit_speed_rad_s: Bit speed at ``t = 0`` in [0, 1000] rad/s; default
            ``0.9 Omega_0``.
        step_s: Integration step in [1e-7, 1e-4], s.
        surface: ``"max"`` or ``"delay"`` (``drill_env.coupled.SURFACE_RULES``).

    Raises:
        ValueError, TypeError: naming the argument and its allowed range.
    """
    p = _resolve(bit)
    chain = coupled_chain(string, axial)
    steady = chain_steady_state(chain, p, top_drive_speed_rad_s, applied_force_n)
    omega0 = float(top_drive_speed_rad_s)
    duration = check_range("duration_s", duration_s, 0.0, 1e6)
    require("duration_s", duration_s, "(0, 1e+06] s", duration > 0)
    h = check_range("step_s", step_s, 1e-7, 1e-4)
    check_choice("surface", surface, SURFACE_RULES, "surface rule")
    n_steps = max(1, math.ceil(duration / h - 1e-9))
    require(
        "duration_s", duration_s, f"at most {MAX_SAMPLES} steps of step_s = {h:g} s",
        n_steps <= MAX_SAMPLES,
    )  # fmt: skip
    om_start = (
        0.9 * omega0
        if initial_bit_speed_rad_s is None
        else check_range("initial_bit_speed_rad_s", initial_bit_speed_rad_s, 0.0, 1e3)
    )
    q = parameter_vector(
        chain, p, axial_top=axial_top, applied_force_n=applied_force_n,
        hook_speed_m_s=hook_speed_m_s, hook_stiffness_n_m=hook_stiffness_n_m, surface=surface,
    )  # fmt: skip
    n = chain.n_nodes
    y = steady_chain_state(chain, steady, omega0)
    y[2 * n - 2] = om_start
    if int(q[_Q_AXIAL_TOP]) == _MODE_SPRING:
        y[4 * n - 2] = applied_force_n / q[_Q_HOOK_K]  # the hook line carries W_0
    if int(q[_Q_AXIAL_TOP]) == _MODE_RIGID:
        y[2 * n - 1] = q[_Q_HOOK_V]
    ring_phi, ring_r, ring = new_surface_ring(p, steady.surface_slope_m_rad)
    out = np.full((n_steps + 1, _N_R), np.nan)
    regime = np.zeros(n_steps + 1, dtype=np.int8)
    acc = np.zeros(3)
    done = int(_simulate_kernel(y, q, n_steps, h, ring_phi, ring_r, ring, out, regime, acc)) + 1
    out = out[:done]
    return FieldCoupledTrace(
        time_s=np.arange(done, dtype=np.float64) * h,
        bit_speed_rad_s=out[:, _R_OM],
        axial_speed_m_s=out[:, _R_V],
        depth_m=out[:, _R_U],
        bit_angle_rad=out[:, _R_PHI],
        weight_on_bit_n=out[:, _R_W],
        torque_on_bit_nm=out[:, _R_T],
        depth_of_cut_m=out[:, _R_DN],
        regime=regime[:done],
        top_torque_nm=out[:, _R_TOP_TORQUE],
        stored_energy_j=out[:, _R_STORED],
        work_in_j=out[:, _R_IN],
        dissipated_j=out[:, _R_DISS],
        bit_work_j=out[:, _R_BIT],
        switch_loss_j=out[:, _R_LOSS],
        steady=steady,
        step_s=h,
        diverged=done < n_steps + 1,
    )


# ---------------------------------------------------------------------------------------------
# The closed loop of DrillStringField-v0 with bit="rgd"
# ---------------------------------------------------------------------------------------------

ENV_STEP_S: Final = 1e-4
"""Integration step of the coupled string in the env: each plant step of ``PLANT_DT_S`` is
taken in equal steps of this length with the torque and applied force held."""
ENV_SPACING_FRACTION: Final = 1e-4
"""The env stores the rock surface at most every ``1e-4`` blade angles (a smaller ring)."""
ENV_RING_CAPACITY: Final = math.ceil(_RING_SPAN / ENV_SPACING_FRACTION) + 16
"""Samples of the rock surface each string of the env keeps."""

# Columns of the per-string outputs of the coupled loop.
OUT_WOB, OUT_TOB, OUT_ROP, OUT_DEPTH, OUT_OFF_BOTTOM, OUT_WOB_MEAN = range(6)
N_OUT: Final = 6


class CoupledArrays(NamedTuple):
    """The per-string arrays of the coupled strings of a batch (N strings), beside
    :class:`drill_env.kernel.BatchArrays` (whose ``x`` holds the torsional part of ``y``).

    Attributes:
        y: Coupled states, (N, state_size(n_max)) (layout in the module docstring).
        q: Parameter vectors (:func:`parameter_vector`), (N, length for n_max).
        regime: Bit regimes (``drill_env.coupled.REGIME_NAMES``), (N,) int64.
        ring_phi, ring_r: Rock-surface rings (angles, rad; depths, m), (N, ENV_RING_CAPACITY).
        ring: Ring indices (first, last, cursor), (N, 3) int64.
        work: Scratch, (N, 9, max(state size, 8)).
        acc: Switch statistics (:func:`coupled_chain_step`), (N, 3).
        out: Per-call outputs (``OUT_*``): weight and torque on bit at the end (N, N m), rate of
            penetration over the call (m/s), bit depth (m), 1.0 when off the rock at the end,
            mean weight on bit over the call (N); (N, N_OUT).
        sources: Entries of the observation's source vector this loop fills (weight on bit,
            rate of penetration), (2,) int64.
    """

    y: npt.NDArray[np.float64]
    q: npt.NDArray[np.float64]
    regime: npt.NDArray[np.int64]
    ring_phi: npt.NDArray[np.float64]
    ring_r: npt.NDArray[np.float64]
    ring: npt.NDArray[np.int64]
    work: npt.NDArray[np.float64]
    acc: npt.NDArray[np.float64]
    out: npt.NDArray[np.float64]
    sources: npt.NDArray[np.int64]


@njit(cache=True)
def _coupled_plant_step(
    y: np.ndarray, saved: np.ndarray, regime: int, u: float, force: float, dt: float,
    q: np.ndarray, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray, work: np.ndarray,
    acc: np.ndarray,
) -> tuple[int, bool, float]:  # fmt: skip
    """One plant step of ``dt`` (s) of the coupled string under the top-drive torque ``u``
    (N m) and applied force ``force`` (N), in steps of at most ``ENV_STEP_S``. Returns the new
    regime, whether the step was accepted (finite and within the speed and twist bounds; else
    ``y`` is restored) and the time integral of the weight on bit (N s)."""
    n = int(q[_Q_N])
    size = y.shape[0]
    for i in range(size):
        saved[i] = y[i]
    q[_Q_TOP_TORQUE] = u
    q[_Q_FORCE] = force
    count = max(1, int(math.ceil(dt / ENV_STEP_S - 1e-9)))
    h = dt / count
    new = regime
    wob_integral = 0.0
    for _ in range(count):
        new = coupled_chain_step(y, new, h, q, ring_phi, ring_r, ring, work, acc)
        dn, f_ax, ts, w, tq = _bit_forces(new, y, q, ring_phi, ring_r, ring, y[4 * n - 3])
        wob_integral += w * h
    ok = True
    for i in range(2 * n - 1):
        limit = MAX_SPEED_RAD_S if i % 2 == 0 else MAX_TWIST_RAD
        if not abs(y[i]) <= limit:
            ok = False
    for i in range(2 * n - 1, size):
        if not math.isfinite(y[i]):
            ok = False
    if not ok:
        for i in range(size):
            y[i] = saved[i]
        return regime, False, 0.0
    return new, True, wob_integral


@njit(cache=True)
def _advance_coupled_one(i, b, s, c):
    """One coupled string of the field env: :func:`drill_env.kernel._advance_chain_one` with
    the coupled plant step (the bit's regime in ``c.regime``; the kernel's slip mode reads
    stuck while the bit does not rotate)."""
    p = b.plant[i]
    xs = b.x[i]
    probes = b.probes[i]
    n = int(p[CP_N])
    size = 2 * n - 1
    y = c.y[i]
    q = c.q[i]
    work = c.work[i]
    saved = work[8]
    ints = b.ints[i]
    f = b.scalars[i]
    ch = b.channel[i]
    prof = b.profiles[i]
    regime = c.regime[i]
    mi = STUCK if regime >= _STUCK else 1
    lp = b.law_params[i]
    ls = b.law_state[i]
    rep = b.report[i]
    rec = b.records[i]
    meas = b.measurement[i]
    hold = ch[CH_HOLD:CH_TELEMETRY]
    tel = ch[CH_TELEMETRY:CH_ACTUATOR]
    tel_buf = b.telemetry_buffer[i]
    act = ch[CH_ACTUATOR:N_CHANNEL]
    line = b.delay_line[i]
    noise = b.noise[i]
    sensor = b.sensor_noise[i]
    wob_t, wob_v, wob_n = prof[PROF_WOB_T], prof[PROF_WOB_V], ints[I_WOB_KNOTS]
    ref_t, ref_v, ref_n = prof[PROF_REF_T], prof[PROF_REF_V], ints[I_REF_KNOTS]
    std, torque_std, tel_std = f[F_NOISE_STD], f[F_TORQUE_NOISE_STD], f[F_TELEMETRY_NOISE_STD]
    command = f[F_COMMAND]
    external = f[F_BASE_TORQUE]
    k = ints[I_STEP]
    row = ints[I_NOISE_POS]
    active = ints[I_STATUS] == STATUS_OK
    ok = active
    u_prev = f[F_LAST_TORQUE]
    u_base_last = rep[REP_BASE_TORQUE]
    command_last = f[F_LAST_COMMAND]
    wob = rep[REP_WOB]
    tracking = 0.0
    variation = 0.0
    torque_squared = 0.0
    residual_squared = 0.0
    stuck = 0.0
    n_done = 0
    depth_start = y[4 * n - 1]
    wob_integral = 0.0
    for j in range(s.n_sub):
        if not ok:
            for col in range(N_RECORD):
                rec[j, col] = math.nan
            continue
        t = k * s.dt
        wob = profile_value(wob_t, wob_v, wob_n, t)
        ref = profile_value(ref_t, ref_v, ref_n, t)
        xi = chain_probe_state(xs, probes)
        surface = chain_surface_torque(xs, p)
        _sense(meas, hold, tel, tel_buf, s, k, xi, surface, std, torque_std, tel_std, u_prev,
               noise, sensor, row + j)  # fmt: skip
        gain = _slot(ls, s.gain_slot)
        u_base = _base_torque(s, lp, ls, meas, external, ref)
        u_command, u = _command_and_torque(s, act, line, u_base, command)
        _record(rec, j, xi, mi, u, u_command, ref, u_base, wob, _slot(ls, s.error_slot), gain,
                surface)  # fmt: skip
        tracking += tracking_error(ref, xi[X_BIT_SPEED])
        variation += abs(u - u_prev)
        torque_squared += u * u
        residual = u - residual_base(s, u_base)
        residual_squared += residual * residual
        u_prev = u
        u_base_last = u_base
        command_last = u_command
        if mi == STUCK:
            stuck += 1.0
        n_done += 1
        accepted = False
        if math.isfinite(u):
            regime, accepted, w_int = _coupled_plant_step(
                y, saved, regime, u, wob, s.dt, q, c.ring_phi[i], c.ring_r[i], c.ring[i], work,
                c.acc[i],
            )  # fmt: skip
        if accepted:
            wob_integral += w_int
            k += 1
            mi = STUCK if regime >= _STUCK else 1
            for col in range(size):
                xs[col] = y[col]
        else:
            ok = False
            ints[I_STATUS] = STATUS_DIVERGED
    _sums(rep, tracking, variation, stuck, n_done, torque_squared, residual_squared)
    if not active:
        return
    c.regime[i] = regime
    ints[I_MODE] = mi
    ints[I_STEP] = k
    f[F_LAST_TORQUE] = u_prev
    f[F_LAST_COMMAND] = command_last
    row += s.n_sub
    ints[I_NOISE_POS] = row
    xi = chain_probe_state(xs, probes)
    _sense(meas, hold, tel, tel_buf, s, k, xi, chain_surface_torque(xs, p), std, torque_std,
           tel_std, u_prev, noise, sensor, row)  # fmt: skip
    src = b.sources[i]
    node_noise = b.node_noise[i]
    for col in range(size):  # the measured state of every node
        src[SRC_STATE + col] = xs[col] + std * node_noise[col // 2] if col % 2 == 0 else xs[col]
    coupled_outputs(i, c, n_done * s.dt, depth_start, wob_integral)
    src[c.sources[0]] = c.out[i, OUT_WOB]
    src[c.sources[1]] = c.out[i, OUT_ROP]
    _finish(i, b, s, xi, mi, k, wob, u_base_last, command_last)


def string_rows(c: CoupledArrays, i: int) -> CoupledArrays:
    """The views of string ``i``'s rows of ``c`` (a batch of one string; ``sources`` as is)."""
    return CoupledArrays._make(
        value if name == "sources" else value[i : i + 1]
        for name, value in zip(CoupledArrays._fields, c, strict=True)
    )


@njit(cache=True)
def coupled_outputs(i, c, span_s: float, depth_start: float, wob_integral: float) -> None:
    """Fill ``c.out[i]`` at the end of a call that lasted ``span_s`` seconds (0: the start of
    an episode, then the rate of penetration is 0 and the mean weight the weight now)."""
    q = c.q[i]
    y = c.y[i]
    n = int(q[_Q_N])
    regime = c.regime[i]
    dn, f_ax, ts, w, tq = _bit_forces(
        regime, y, q, c.ring_phi[i], c.ring_r[i], c.ring[i], y[4 * n - 3]
    )
    out = c.out[i]
    out[OUT_WOB] = w
    out[OUT_TOB] = tq
    out[OUT_DEPTH] = y[4 * n - 1]
    out[OUT_ROP] = (y[4 * n - 1] - depth_start) / span_s if span_s > 0 else 0.0
    out[OUT_OFF_BOTTOM] = 1.0 if regime in (_AIR, _STUCK_AIR) else 0.0
    out[OUT_WOB_MEAN] = wob_integral / span_s if span_s > 0 else w


@njit(cache=True)
def advance_coupled_batch(b, s, c):
    """:func:`drill_env.kernel.advance_chain_batch` for coupled strings (``bit="rgd"``)."""
    _check_noise_room(b.noise, b.ints, s.n_sub)
    for i in range(b.x.shape[0]):
        _advance_coupled_one(i, b, s, c)


@njit(cache=True, parallel=True)
def advance_coupled_batch_parallel(b, s, c):
    """:func:`advance_coupled_batch` with the strings spread over numba's threads."""
    _check_noise_room(b.noise, b.ints, s.n_sub)
    for i in prange(b.x.shape[0]):
        _advance_coupled_one(i, b, s, c)


def rest_state(chain: CoupledChain, applied_force_n: float) -> FloatArray:
    """The coupled state of a string at rest on the bottom under the applied force: no
    motion, no twist, every element compressed by the force (energy integrals 0)."""
    n = chain.n_nodes
    y = np.zeros(state_size(n))
    a = 2 * n - 1
    y[a + 1 : a + 2 * n - 1 : 2] = applied_force_n / chain.axial.element_stiffness_n_m
    return y


def rest_surface_slope_m_rad(
    chain: CoupledChain, bit: RgdParameters, top_drive_speed_rad_s: float, applied_force_n: float
) -> float:
    """Slope ``r`` (m/rad) of the rock surface left by steady drilling at this speed and
    force (0 when the force does not exceed the wear-flat force): the history of a bit put
    down at rest in the hole it drilled."""
    speed = max(float(top_drive_speed_rad_s), 1e-6)
    damping = float(chain.axial.node_damping_ns_m.sum())
    depth = max(applied_force_n - bit.contact_force_n, 0.0) / (
        bit.k_a + damping * bit.blades * speed / (2 * math.pi)
    )
    return bit.blades * depth / (2 * math.pi)


BIT_LAWS: Final = ("karnopp", "rgd")
"""Bit laws of ``DrillStringField-v0``: Karnopp's velocity-weakening friction (the default) or
the regenerative RGD bit on a string with axial elements."""


def coupled_arrays(num: int, max_nodes: int, sources: tuple[int, int]) -> CoupledArrays:
    """Zeroed :class:`CoupledArrays` for ``num`` strings of up to ``max_nodes`` nodes whose
    weight on bit and rate of penetration go to the source-vector entries ``sources``."""
    size = state_size(max_nodes)
    return CoupledArrays(
        y=np.zeros((num, size)),
        q=np.zeros((num, _parameter_length(max_nodes))),
        regime=np.zeros(num, dtype=np.int64),
        ring_phi=np.zeros((num, ENV_RING_CAPACITY)),
        ring_r=np.zeros((num, ENV_RING_CAPACITY)),
        ring=np.zeros((num, 3), dtype=np.int64),
        work=np.zeros((num, 9, max(size, 8))),
        acc=np.zeros((num, 3)),
        out=np.zeros((num, N_OUT)),
        sources=np.array(sources, dtype=np.int64),
    )


def reset_coupled_string(
    c: CoupledArrays,
    i: int,
    string: DistributedStringParameters,
    bit: RgdParameters,
    *,
    axial_top: str,
    hook_speed_m_s: float | None,
    hook_stiffness_n_m: float,
    applied_force_n: float,
    reference_speed_rad_s: float,
) -> FloatArray:
    """Put string ``i`` of ``c`` at rest on the bottom of the hole it drilled at the reference
    speed and applied force (:func:`rest_state`, :func:`rest_surface_slope_m_rad`), the hook
    line preloaded to the applied force, the bit's regime from the rules (stuck on the rock).
    Returns the torsional part of the state ``(2 n - 1,)``."""
    chain = coupled_chain(string)
    n = chain.n_nodes
    q = parameter_vector(
        chain, bit, axial_top=axial_top, applied_force_n=applied_force_n,
        hook_speed_m_s=hook_speed_m_s, hook_stiffness_n_m=hook_stiffness_n_m,
        top_speed_held=False,
    )  # fmt: skip
    q[_P_SPACING] = ENV_SPACING_FRACTION * bit.blade_angle_rad
    y = rest_state(chain, applied_force_n)
    if int(q[_Q_AXIAL_TOP]) == _MODE_SPRING:
        y[4 * n - 2] = applied_force_n / q[_Q_HOOK_K]
    elif int(q[_Q_AXIAL_TOP]) == _MODE_RIGID:
        y[2 * n - 1] = q[_Q_HOOK_V]
    slope = rest_surface_slope_m_rad(chain, bit, reference_speed_rad_s, applied_force_n)
    c.ring_phi[i] = 0.0
    c.ring_r[i] = 0.0
    c.ring_phi[i, 0] = -3.0 * bit.blade_angle_rad
    c.ring_r[i, 0] = slope * c.ring_phi[i, 0]
    c.ring[i] = (0, 1, 0)
    c.q[i] = 0.0
    c.q[i, : q.shape[0]] = q
    c.y[i] = 0.0
    c.y[i, : y.shape[0]] = y
    c.work[i] = 0.0
    c.acc[i] = 0.0
    c.regime[i] = initial_regime(
        c.y[i, : y.shape[0]], c.q[i], c.ring_phi[i], c.ring_r[i], c.ring[i]
    )
    coupled_outputs(i, c, 0.0, 0.0, 0.0)
    return c.y[i, : 2 * n - 1].copy()


def coupled_info(c: CoupledArrays) -> dict[str, npt.NDArray[np.float64] | npt.NDArray[np.bool_]]:
    """The ``info`` entries of the coupled strings after the last step, (N,) each:
    ``weight_on_bit_n`` and ``torque_on_bit_nm`` (at the end), ``mean_weight_on_bit_n`` and
    ``rate_of_penetration_m_s`` (over the step), ``bit_depth_m`` (from the start of the
    episode), ``bit_off_bottom``."""
    out = c.out
    return {
        "weight_on_bit_n": out[:, OUT_WOB].copy(),
        "torque_on_bit_nm": out[:, OUT_TOB].copy(),
        "mean_weight_on_bit_n": out[:, OUT_WOB_MEAN].copy(),
        "rate_of_penetration_m_s": out[:, OUT_ROP].copy(),
        "bit_depth_m": out[:, OUT_DEPTH].copy(),
        "bit_off_bottom": out[:, OUT_OFF_BOTTOM] > 0.5,
    }


def check_bit_keywords(
    bit: str,
    rgd_parameters: object,
    axial_top: str,
    hook_speed_m_s: float | None,
    hook_stiffness_n_m: float,
) -> RgdParameters | None:
    """Validate the bit keywords of ``DrillStringField-v0``; the RGD parameters with
    ``bit="rgd"``, else ``None`` (then the other keywords must keep their defaults)."""
    check_choice("bit", bit, BIT_LAWS, "bit law")
    if bit == "karnopp":
        for name, value, default in (
            ("rgd_parameters", rgd_parameters, "rgd_a"), ("axial_top", axial_top, "force"),
            ("hook_speed_m_s", hook_speed_m_s, None),
            ("hook_stiffness_n_m", hook_stiffness_n_m, math.inf),
        ):  # fmt: skip
            if not (value is default or value == default):
                raise ValueError(f"{name} = {shown(value)} applies only with bit='rgd'")
        return None
    p = _resolve(rgd_parameters, "rgd_parameters")  # type: ignore[arg-type]
    _check_top(axial_top, hook_speed_m_s, hook_stiffness_n_m)
    return p
