"""``DrillStringCoupled-v0``: the paper's 4-DOF torsional string with an axial BHA mass and the
regenerative (RGD) bit in place of the Karnopp friction law (docs/coupled-model.md section 11).

The torsional chain (top drive, pipes, collars, bit) is the one of ``DrillString-v0``
(:class:`drill_env.parameters.DrillStringParameters`); the bit DOF also moves axially with
the mass ``M`` of :class:`drill_env.coupled.RgdParameters`, pushed down by the applied force,
and meets the rock through the RGD bit law with its rock-surface memory
(:func:`drill_env.coupled.bit_load`, :func:`drill_env.coupled.switching_functions`,
:func:`drill_env.coupled.switch_rule`: one home). The plant advances by fixed RK4 steps of
``1e-4 s`` with every regime switch located inside the step, the inputs held over each
decision.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Final, NamedTuple, NoReturn, Protocol, SupportsFloat, runtime_checkable

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium.envs.registration import EnvSpec
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numba import njit

from drill_env import render
from drill_env.control import (
    CompiledController,
    CompiledLaw,
    call_law,
    compile_law,
    controller_names,
    resolve_controller,
)
from drill_env.coupled import (
    _AIR,
    _DOWN,
    _HOLD,
    _N_P,
    _P_BLADE,
    _P_CA,
    _P_CT,
    _P_I,
    _P_K,
    _P_M,
    _P_VTOP,
    _P_W0,
    _RING_SPAN,
    _SPACING_FRACTION,
    _STUCK,
    _STUCK_AIR,
    RGD_PRESETS,
    RgdParameters,
    _from_rest,
    _kernel_parameters,
    _record,
    _surface,
    bit_load,
    illinois_update,
    steady_state,
    stop_rule,
    switch_rule,
    switching_functions,
)
from drill_env.env import (
    EpisodeStepsSpec,
    copy_env_attributes,
    refuse_pickling,
    validate_actions,
)
from drill_env.layout import (
    M_APPLIED_TORQUE,
    M_STATE,
    M_SURFACE_TORQUE,
    M_TELEMETRY_AGE,
    M_TELEMETRY_BIT_SPEED,
    M_TOP_DRIVE_SPEED,
    N_MEASUREMENT,
)
from drill_env.limits import (
    HOOK_STIFFNESS_RANGE_N_M,
    MAX_BATCH_BYTES,
    MAX_EPISODE_S,
    MAX_NUM_ENVS,
    MAX_SPEED_RAD_S,
    TorqueLimits,
)
from drill_env.options import check_episode_s
from drill_env.parameters import PLANT_DT_S, PRESETS, DrillStringParameters
from drill_env.rewards import DIVERGED_REWARD
from drill_env.validation import (
    check_choice,
    check_finite_fields,
    check_int,
    check_range,
    check_seeds,
    check_unknown,
    input_type_errors,
    require,
    shown,
)

__all__ = [
    "ACTION_MODES",
    "OBSERVATION_NAMES",
    "CoupledEnvConfig",
    "CoupledRewardWeights",
    "AXIAL_INPUTS",
    "AxialController",
    "AxialMeasurement",
    "AxialSetup",
    "DrillStringCoupledEnv",
    "DrillStringCoupledVectorEnv",
    "axial_controller_names",
    "make_axial_controller",
    "register_axial_controller",
]

PLANT_STEP_S: Final = 1e-4
"""Plant integration step of the coupled env, s."""

# Extra entries of the kernel parameter vector (after the bit's, drill_env.coupled._N_P).
_Q_J_DT, _Q_J_PI, _Q_J_CO = _N_P, _N_P + 1, _N_P + 2
_Q_C_DT, _Q_C_PI, _Q_C_CO, _Q_C_BI = _N_P + 3, _N_P + 4, _N_P + 5, _N_P + 6
_Q_K_PI, _Q_K_CO, _Q_K_BI, _Q_TORQUE = _N_P + 7, _N_P + 8, _N_P + 9, _N_P + 10
_N_Q = _N_P + 11

# State vector: bit depth and axial speed, bit angle and speed, then the chain.
_Y_U, _Y_V, _Y_PHI, _Y_OM, _Y_PHI_DT, _Y_PHI_PI, _Y_PHI_CO, _Y_OM_DT, _Y_OM_PI, _Y_OM_CO = range(10)
_N_Y = 10

# Accumulators of one call of the kernel.
_A_STUCK, _A_OFF, _A_HOLD, _A_TD_WORK, _A_BIT_WORK, _A_WOB, _A_TOB, _A_SPEED_ERR = range(8)
_A_OM_MIN, _A_OM_MAX, _A_LOSS, _A_SWITCHES, _A_DONE, _A_TORQUE = range(8, 14)
_N_A = 14

_MAX_SWITCHES: Final = 32


@njit(cache=True)
def _chain_forces(
    regime: int, t: float, y: np.ndarray, p: np.ndarray, ring_phi: np.ndarray,
    ring_r: np.ndarray, ring: np.ndarray, v_axial: float,
) -> tuple[float, float, float, float, float]:  # fmt: skip
    """``(d_n, F_ax, T_s, W, T)`` at the state ``y``: the string torque on the bit is the
    collar-to-bit coupling ``k_bi (phi_co - phi_bi) + c_bi (w_co - w_bi)``; ``v_axial`` (m/s)
    is the axial speed used in ``F_ax``."""
    u = y[_Y_U]
    dn = u - _surface(y[_Y_PHI] - p[_P_BLADE], ring_phi, ring_r, ring)
    f_ax = p[_P_W0] + p[_P_K] * (p[_P_VTOP] * t - u) - p[_P_CA] * v_axial
    ts = p[_Q_K_BI] * (y[_Y_PHI_CO] - y[_Y_PHI]) + p[_Q_C_BI] * (y[_Y_OM_CO] - y[_Y_OM])
    w, tq = bit_load(regime, dn, f_ax, ts, p)
    return dn, f_ax, ts, w, tq


@njit(cache=True)
def _chain_rhs(
    regime: int, t: float, y: np.ndarray, dy: np.ndarray, p: np.ndarray,
    ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> None:  # fmt: skip
    """Write ``dy/dt`` of the state ``y`` (10,) in the frozen regime into ``dy``."""
    dn, f_ax, ts, w, tq = _chain_forces(regime, t, y, p, ring_phi, ring_r, ring, y[_Y_V])
    t_pi = p[_Q_K_PI] * (y[_Y_PHI_DT] - y[_Y_PHI_PI]) + p[_Q_C_PI] * (y[_Y_OM_DT] - y[_Y_OM_PI])
    t_co = p[_Q_K_CO] * (y[_Y_PHI_PI] - y[_Y_PHI_CO]) + p[_Q_C_CO] * (y[_Y_OM_PI] - y[_Y_OM_CO])
    dy[_Y_PHI_DT] = y[_Y_OM_DT]
    dy[_Y_PHI_PI] = y[_Y_OM_PI]
    dy[_Y_PHI_CO] = y[_Y_OM_CO]
    dy[_Y_OM_DT] = (p[_Q_TORQUE] - p[_Q_C_DT] * y[_Y_OM_DT] - t_pi) / p[_Q_J_DT]
    dy[_Y_OM_PI] = (t_pi - t_co) / p[_Q_J_PI]
    dy[_Y_OM_CO] = (t_co - ts) / p[_Q_J_CO]
    if regime == _STUCK:
        dy[_Y_U] = 0.0
        dy[_Y_V] = 0.0
        dy[_Y_PHI] = 0.0
        dy[_Y_OM] = 0.0
        return
    if regime == _STUCK_AIR:
        dy[_Y_U] = y[_Y_V]
        dy[_Y_V] = f_ax / p[_P_M]
        dy[_Y_PHI] = 0.0
        dy[_Y_OM] = 0.0
        return
    dy[_Y_PHI] = y[_Y_OM]
    dy[_Y_OM] = (ts - p[_P_CT] * y[_Y_OM] - tq) / p[_P_I]
    if regime == _HOLD:
        dy[_Y_U] = 0.0
        dy[_Y_V] = 0.0
    else:
        dy[_Y_U] = y[_Y_V]
        dy[_Y_V] = (f_ax - w) / p[_P_M]


@njit(cache=True)
def _chain_rk4(
    regime: int, t: float, y: np.ndarray, dt: float, out: np.ndarray, work: np.ndarray,
    p: np.ndarray, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> None:  # fmt: skip
    """One RK4 step of ``dt`` (s) from ``y`` into ``out``; ``work`` is (5, 10) scratch."""
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    _chain_rhs(regime, t, y, k1, p, ring_phi, ring_r, ring)
    hh = 0.5 * dt
    for i in range(_N_Y):
        tmp[i] = y[i] + hh * k1[i]
    _chain_rhs(regime, t + hh, tmp, k2, p, ring_phi, ring_r, ring)
    for i in range(_N_Y):
        tmp[i] = y[i] + hh * k2[i]
    _chain_rhs(regime, t + hh, tmp, k3, p, ring_phi, ring_r, ring)
    for i in range(_N_Y):
        tmp[i] = y[i] + dt * k3[i]
    _chain_rhs(regime, t + dt, tmp, k4, p, ring_phi, ring_r, ring)
    s = dt / 6.0
    for i in range(_N_Y):
        out[i] = y[i] + s * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def _chain_events(
    g: np.ndarray, regime: int, t: float, y: np.ndarray, p: np.ndarray,
    ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> None:  # fmt: skip
    dn, f_ax, ts, w, tq = _chain_forces(regime, t, y, p, ring_phi, ring_r, ring, y[_Y_V])
    switching_functions(g, regime, dn, f_ax, ts, y[_Y_V], y[_Y_OM], p)


@njit(cache=True)
def _chain_switch(
    regime: int, which: int, t: float, y: np.ndarray, p: np.ndarray,
    ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> tuple[int, float]:  # fmt: skip
    """Apply switch ``which`` to ``y`` in place; ``(new regime, energy removed J)``."""
    dn, f_rest, ts, w, tq = _chain_forces(regime, t, y, p, ring_phi, ring_r, ring, 0.0)
    new, v, om, loss = switch_rule(regime, which, dn, f_rest, ts, y[_Y_V], y[_Y_OM], p)
    y[_Y_V] = v
    y[_Y_OM] = om
    return new, loss


@njit(cache=True)
def _chain_locate(
    which: int, regime: int, t: float, y: np.ndarray, dt: float, g_start: float,
    g_end: float, tolerance: float, g: np.ndarray, trial: np.ndarray, work: np.ndarray,
    p: np.ndarray, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
) -> float:  # fmt: skip
    """Time (s, from ``t``) at which switching function ``which`` turns negative along the
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
        _chain_rk4(regime, t, y, c, trial, work, p, ring_phi, ring_r, ring)
        _chain_events(g, regime, t + c, trial, p, ring_phi, ring_r, ring)
        fc = g[which]
        if not (fc < 0.0 or fc > 0.0):
            return c
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
    return b


@njit(cache=True)
def _chain_initial_regime(
    y: np.ndarray, p: np.ndarray, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray
) -> int:
    """Regime of the state ``y`` at ``t = 0`` (its speeds set consistently in place)."""
    dn, f_rest, ts, w, tq = _chain_forces(_DOWN, 0.0, y, p, ring_phi, ring_r, ring, 0.0)
    if y[_Y_OM] <= 0.0:
        regime, v, om, loss = stop_rule(dn, f_rest, ts, y[_Y_V], 0.0, p)
        y[_Y_V] = v
        y[_Y_OM] = om
        return regime
    if dn < 0.0:
        return _AIR
    if y[_Y_V] > 0.0:
        return _DOWN
    if y[_Y_V] < 0.0:
        return 1  # up
    return _from_rest(dn, f_rest, p)


@njit(cache=True)
def _measure(y: np.ndarray, p: np.ndarray, meas: np.ndarray) -> None:
    """Fill the measurement vector ``meas`` (``drill_env.layout.M_*``) from the state ``y``:
    the 4-DOF state ``(w_dt, phi_dt - phi_pi, w_pi, phi_pi - phi_co, w_co, phi_co - phi_bi,
    w_bi)`` measured exactly, the top-drive speed and the surface torque, no telemetry."""
    meas[M_STATE] = y[_Y_OM_DT]
    meas[M_STATE + 1] = y[_Y_PHI_DT] - y[_Y_PHI_PI]
    meas[M_STATE + 2] = y[_Y_OM_PI]
    meas[M_STATE + 3] = y[_Y_PHI_PI] - y[_Y_PHI_CO]
    meas[M_STATE + 4] = y[_Y_OM_CO]
    meas[M_STATE + 5] = y[_Y_PHI_CO] - y[_Y_PHI]
    meas[M_STATE + 6] = y[_Y_OM]
    meas[M_TOP_DRIVE_SPEED] = y[_Y_OM_DT]
    meas[M_SURFACE_TORQUE] = p[_Q_K_PI] * (y[_Y_PHI_DT] - y[_Y_PHI_PI]) + p[_Q_C_PI] * (
        y[_Y_OM_DT] - y[_Y_OM_PI]
    )
    meas[M_TELEMETRY_BIT_SPEED] = math.nan
    meas[M_TELEMETRY_AGE] = math.nan


@njit(cache=True)
def _chain_advance(
    p: np.ndarray, y: np.ndarray, regime_box: np.ndarray, t0: float, n_steps: int, h: float,
    reference: float, ring_phi: np.ndarray, ring_r: np.ndarray, ring: np.ndarray,
    acc: np.ndarray, work: np.ndarray, law_address: int, law_params: np.ndarray,
    law_state: np.ndarray, meas: np.ndarray, residual_torque: float, max_torque: float,
) -> None:  # fmt: skip
    """Advance the state ``y`` (10,) in place by ``n_steps`` steps of ``h`` (s) from time
    ``t0`` under the inputs in ``p``; ``regime_box[0]`` holds the regime. With a compiled
    torque law (``law_address`` not 0), the top-drive torque is the law's output on the
    measurement ``meas`` (the 4-DOF state and the surface signals, ``drill_env.layout.M_*``)
    plus ``residual_torque``, clipped to ``[0, max_torque]`` (N m), at every step. ``acc`` (13,) gets
    this call's sums (stuck, off-rock and held time, s; top-drive and bit work, J; time
    integrals of WOB, N s, TOB, N m s, and of ``|w_bi - reference|``, rad), the least and
    greatest bit speed, the energy removed at switches, the switches and the steps done (fewer
    when the state stopped being finite or a speed left ``MAX_SPEED_RAD_S``)."""
    g0 = np.empty(4)
    g1 = np.empty(4)
    gc = np.empty(4)
    trial = np.empty(_N_Y)
    trial2 = np.empty(_N_Y)
    saved = np.empty(_N_Y)
    regime = regime_box[0]
    acc[:] = 0.0
    acc[_A_OM_MIN] = y[_Y_OM]
    acc[_A_OM_MAX] = y[_Y_OM]
    tolerance = 1e-13 * h
    t = t0
    for k in range(n_steps):
        t_end = t0 + (k + 1) * h
        switches = 0
        om_dt_start = y[_Y_OM_DT]
        if law_address != 0:
            _measure(y, p, meas)
            raw: float = call_law(  # type: ignore[call-arg]
                law_address, law_params, law_state, meas, reference, h
            )
            torque = min(max(raw + residual_torque, 0.0), max_torque)
            meas[M_APPLIED_TORQUE] = torque
            p[_Q_TORQUE] = torque
        for i in range(_N_Y):
            saved[i] = y[i]
        while True:
            dt = t_end - t
            if dt <= 0.0:
                break
            _chain_events(g0, regime, t, y, p, ring_phi, ring_r, ring)
            live = switches < _MAX_SWITCHES
            if live:
                now = -1
                for i in range(4):
                    if g0[i] < 0.0:
                        now = i
                        break
                if now >= 0:
                    regime, loss = _chain_switch(regime, now, t, y, p, ring_phi, ring_r, ring)
                    acc[_A_LOSS] += loss
                    acc[_A_SWITCHES] += 1
                    switches += 1
                    continue
            _chain_rk4(regime, t, y, dt, trial, work, p, ring_phi, ring_r, ring)
            _chain_events(g1, regime, t_end, trial, p, ring_phi, ring_r, ring)
            first = -1
            when = dt
            if live:
                for i in range(4):
                    if g0[i] > 0.0 and g1[i] < 0.0:
                        at = _chain_locate(
                            i, regime, t, y, dt, g0[i], g1[i], tolerance, gc, trial2, work, p,
                            ring_phi, ring_r, ring,
                        )  # fmt: skip
                        if first < 0 or at < when:
                            first = i
                            when = at
            if first < 0:
                late = -1
                if live:
                    for i in range(4):
                        if g0[i] == 0.0 and g1[i] < 0.0:
                            late = i
                            break
                t = t_end
                for i in range(_N_Y):
                    y[i] = trial[i]
                _record(y[_Y_PHI], y[_Y_U], p, ring_phi, ring_r, ring)
                if late >= 0:
                    regime, loss = _chain_switch(regime, late, t, y, p, ring_phi, ring_r, ring)
                    acc[_A_LOSS] += loss
                    acc[_A_SWITCHES] += 1
                break
            _chain_rk4(regime, t, y, when, trial, work, p, ring_phi, ring_r, ring)
            for i in range(_N_Y):
                y[i] = trial[i]
            t = t_end if when >= dt else t + when
            _record(y[_Y_PHI], y[_Y_U], p, ring_phi, ring_r, ring)
            regime, loss = _chain_switch(regime, first, t, y, p, ring_phi, ring_r, ring)
            acc[_A_LOSS] += loss
            acc[_A_SWITCHES] += 1
            switches += 1
        finite = True
        for i in range(_N_Y):
            if not math.isfinite(y[i]):
                finite = False
        if not finite or abs(y[_Y_OM_DT]) > MAX_SPEED_RAD_S or abs(y[_Y_OM]) > MAX_SPEED_RAD_S:
            for i in range(_N_Y):
                y[i] = saved[i]
            regime_box[0] = regime
            return
        dn, f_ax, ts, w, tq = _chain_forces(regime, t, y, p, ring_phi, ring_r, ring, y[_Y_V])
        if regime >= _STUCK:
            acc[_A_STUCK] += h
        if regime in (_AIR, _STUCK_AIR):
            acc[_A_OFF] += h
        if regime == _HOLD:
            acc[_A_HOLD] += h
        acc[_A_TD_WORK] += p[_Q_TORQUE] * 0.5 * (om_dt_start + y[_Y_OM_DT]) * h
        acc[_A_TORQUE] += p[_Q_TORQUE] * h
        acc[_A_BIT_WORK] += (w * y[_Y_V] + tq * y[_Y_OM]) * h
        acc[_A_WOB] += w * h
        acc[_A_TOB] += tq * h
        acc[_A_SPEED_ERR] += abs(y[_Y_OM] - reference) * h
        acc[_A_OM_MIN] = min(acc[_A_OM_MIN], y[_Y_OM])
        acc[_A_OM_MAX] = max(acc[_A_OM_MAX], y[_Y_OM])
        acc[_A_DONE] = k + 1
    regime_box[0] = regime


# ---------------------------------------------------------------------------------------------
# The environment
# ---------------------------------------------------------------------------------------------

ACTION_MODES: Final = ("both", "torque", "force")
"""What the agent commands: both inputs, the top-drive torque only (the axial input from its
base loop), or the axial input only (the torque from its base loop)."""
TORQUE_LOOPS: Final = ("pi", "none")
"""Built-in base loops of the top-drive torque: a PI speed loop on the top-drive speed (the
action adds a residual) or none (the action is the torque itself). ``torque_loop`` also takes
the name of a registered controller with a compiled law (``drill_env.controller_names()``,
e.g. ``"stiff_pi"``, ``"soft_speed"``, ``"z_torque"``, ``"proposed"``) or such a controller:
its law runs at every plant step on the exact 4-DOF state, the action adding a residual."""
FORCE_LOOPS: Final = ("fixed", "none")
"""Built-in base loops of the axial input: the set point (the action adds a residual) or none
(the action is the input itself). ``force_loop`` also takes the name of a registered axial
controller (:func:`axial_controller_names`, e.g. ``"autodriller"``) or such a controller,
called once per decision, the action adding a residual."""
AXIAL_INPUTS: Final = ("force", "hook_speed")
"""What drives the bit axially: the applied force ``W_0`` (RGD's constant hook load), or the
hook speed ``V_top`` through the axial spring ``K`` of the string (docs/coupled-model.md
section 3: ``F_ax = W_0 + K (x_hook - U)``, the hook position ``x_hook`` integrating the
commanded hook speed from 0, ``W_0`` the force set point at the start)."""


class AxialSetup(NamedTuple):
    """What an axial controller is told at each reset.

    Attributes:
        axial_input: One of :data:`AXIAL_INPUTS`: the unit of the command (N or m/s).
        force_set_point_n: The env's applied-force set point, N.
        rop_reference_m_s: Steady rate of penetration at the set point and the reference
            speed, m/s (also the hook speed that holds the set point in steady drilling).
        min_command: Smallest command, N or m/s.
        max_command: Largest command, N or m/s.
        max_torque_nm: Largest top-drive torque, N m.
    """

    axial_input: str
    force_set_point_n: float
    rop_reference_m_s: float
    min_command: float
    max_command: float
    max_torque_nm: float


class AxialMeasurement(NamedTuple):
    """What an axial controller sees at each decision: means over the last decision.

    Attributes:
        wob_n: Weight on bit, N (a downhole measurement; 0 off the rock).
        rop_m_s: Rate of penetration, m/s.
        surface_torque_nm: Torque at the top of the string at the decision, N m.
        top_drive_torque_nm: Mean top-drive torque, N m.
        command: The axial command held over the last decision, N or m/s.
    """

    wob_n: float
    rop_m_s: float
    surface_torque_nm: float
    top_drive_torque_nm: float
    command: float


@runtime_checkable
class AxialController(Protocol):
    """A driller's loop on the axial input (applied force or hook speed), called per decision."""

    def reset(self, setup: AxialSetup) -> None:
        """Start an episode with ``setup``."""

    def command(self, measurement: AxialMeasurement, dt_s: float) -> float:
        """The axial command (N or m/s, :attr:`AxialSetup.axial_input`) for the next ``dt_s``
        seconds."""
        ...


AXIAL_ENTRY_POINT_GROUP: Final = "drill_string_gym.axial_controllers"
"""Entry point group through which installed packages offer axial controllers by name."""
_AXIAL_FACTORIES: dict[str, Callable[..., AxialController]] = {}


def register_axial_controller(name: str, factory: Callable[..., AxialController]) -> None:
    """Offer ``factory`` under ``name`` as a ``force_loop`` of ``DrillStringCoupled-v0``; the
    same factory twice is harmless, another under a taken name an error."""
    if not isinstance(name, str) or not name or name in FORCE_LOOPS:
        raise ValueError(f"axial controller name must be a new non-empty string, got {shown(name)}")
    known = _AXIAL_FACTORIES.get(name)
    if known is not None and known is not factory:
        raise ValueError(f"axial controller name {shown(name)} is already registered")
    _AXIAL_FACTORIES[name] = factory


def _axial_entry_points() -> dict[str, metadata.EntryPoint]:
    return {e.name: e for e in metadata.entry_points(group=AXIAL_ENTRY_POINT_GROUP)}


def axial_controller_names() -> list[str]:
    """The registered axial controller names (this process's, then the entry points')."""
    return list(dict.fromkeys([*_AXIAL_FACTORIES, *_axial_entry_points()]))


def make_axial_controller(name: str, **gains: Any) -> AxialController:
    """A new axial controller ``name`` (``ValueError`` listing the valid names if unknown)."""
    factory = _AXIAL_FACTORIES.get(name)
    if factory is None:
        entry = _axial_entry_points().get(name)
        if entry is not None:
            factory = entry.load()
            register_axial_controller(name, factory)
    if factory is None:
        raise ValueError(
            f"force_loop = {shown(name)} is not a known axial loop: allowed {list(FORCE_LOOPS)} or "
            f"a registered axial controller {axial_controller_names()}"
        )
    return factory(**gains)


OBSERVATION_NAMES: Final = (
    "top_drive_speed_rel",
    "bit_speed_rel",
    "wob_rel",
    "rop_rel",
    "surface_torque_rel",
    "applied_force_rel",
    "top_drive_torque_rel",
    "off_bottom_fraction",
)
"""The observation's entries: top-drive and bit speed over the reference; weight on bit,
applied force over the force set point; rate of penetration over the steady one at the set
point; surface and top-drive torque over the top drive's largest torque; the fraction of the
last decision spent off the rock."""
OBS_LIMIT: Final = 50.0
"""Every observation entry is clipped to [-OBS_LIMIT, OBS_LIMIT]."""


@dataclass(frozen=True)
class CoupledRewardWeights:
    """Weights of the reward per decision ``r = rop * ROP / V_ref - speed_error * mean|w_bi -
    w_ref| / w_ref - stuck * stuck fraction - bounce * off-rock fraction - energy * P_td /
    P_ref``, with ``V_ref`` the steady rate of penetration at the force set point and the
    reference speed, ``P_td`` the mean top-drive power and ``P_ref`` the steady top-drive
    power there.

    Attributes:
        rop: Weight of the relative rate of penetration, -.
        speed_error: Weight of the relative bit-speed error, -.
        stuck: Weight of the time fraction the bit is stuck, -.
        bounce: Weight of the time fraction the bit is off the rock, -.
        energy: Weight of the relative top-drive power, -.
    """

    rop: float = 1.0
    speed_error: float = 1.0
    stuck: float = 1.0
    bounce: float = 2.0
    energy: float = 0.2

    def __post_init__(self) -> None:
        check_finite_fields(self, "reward_weights.")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            require(f"reward_weights.{f.name}", value, "[0, 1000]", 0 <= value <= 1000)


@dataclass(frozen=True)
class CoupledEnvConfig:
    """Keywords of ``DrillStringCoupled-v0``.

    Attributes:
        string: Torsional string: a preset of :data:`drill_env.parameters.PRESETS` or a
            :class:`drill_env.parameters.DrillStringParameters`.
        bit: Bit and axial mass: a preset of :data:`drill_env.coupled.RGD_PRESETS` or an
            :class:`drill_env.coupled.RgdParameters` (its torsional fields are not used).
        reference_speed_rad_s: Reference bit speed of the speed loop and the reward, rad/s.
        applied_force_n: Set point of the applied force, N (above the wear-flat force); with
            the hook-speed input, the applied force at the start.
        action_mode: One of :data:`ACTION_MODES`.
        torque_loop: One of :data:`TORQUE_LOOPS`, or a registered controller with a compiled
            law (name or object).
        force_loop: One of :data:`FORCE_LOOPS`, or a registered axial controller (name or
            object, :class:`AxialController`).
        axial_input: One of :data:`AXIAL_INPUTS`.
        hook_stiffness_n_m: Axial stiffness ``K`` of the string between hook and bit with the
            hook-speed input, N/m (default: ``E A / L`` of 1000 m of the RGD-A pipe, steel).
        residual_hook_speed_m_s: Hook speed of a residual action of 1, m/s.
        max_hook_speed_m_s: Largest hook speed magnitude, m/s (the range is [-max, max];
            negative lifts).
        speed_loop_kp_nms_rad: Proportional gain of the PI speed loop, N m s/rad.
        speed_loop_ki_nm_rad: Integral gain of the PI speed loop, N m/rad.
        residual_torque_nm: Torque of a residual action of 1 (with the PI loop), N m.
        residual_force_n: Force of a residual action of 1 (with the fixed force), N.
        max_torque_nm: Largest top-drive torque (the range is [0, max]), N m.
        max_force_n: Largest applied force (the range is [0, max]), N.
        control_dt_s: Decision period, s (a multiple of the 1e-4 s plant step).
        episode_s: Episode length, s (truncation; a multiple of ``control_dt_s``).
        randomize: Draw the rock's intrinsic energy (x U[0.8, 1.2]) and the initial bit
            speed (x U[0.8, 1.0]) from the reset seed; otherwise nominal rock and 0.9.
        surface: Rock-surface rule, ``"max"`` or ``"delay"``.
        reward_weights: :class:`CoupledRewardWeights`.
    """

    string: str | DrillStringParameters = "zribi2024"
    bit: str | RgdParameters = "rgd_a"
    reference_speed_rad_s: float = 12.0
    applied_force_n: float = 90e3
    action_mode: str = "both"
    torque_loop: Any = "pi"
    force_loop: Any = "fixed"
    axial_input: str = "force"
    hook_stiffness_n_m: float = 7.26e5
    residual_hook_speed_m_s: float = 0.01
    max_hook_speed_m_s: float = 0.1
    speed_loop_kp_nms_rad: float = 2_000.0
    speed_loop_ki_nm_rad: float = 500.0
    residual_torque_nm: float = 5_000.0
    residual_force_n: float = 30e3
    max_torque_nm: float = 50_000.0
    max_force_n: float = 250e3
    control_dt_s: float = 0.05
    episode_s: float = 30.0
    randomize: bool = True
    surface: str = "max"
    reward_weights: CoupledRewardWeights = field(default_factory=CoupledRewardWeights)

    def __post_init__(self) -> None:
        if isinstance(self.string, str):
            check_choice("string", self.string, PRESETS, "preset")
        elif not isinstance(self.string, DrillStringParameters):
            raise TypeError("string must be a preset name or a DrillStringParameters")
        if isinstance(self.bit, str):
            check_choice("bit", self.bit, RGD_PRESETS, "preset")
        elif not isinstance(self.bit, RgdParameters):
            raise TypeError("bit must be a preset name or an RgdParameters")
        if isinstance(self.reward_weights, dict):
            valid = [f.name for f in dataclasses.fields(CoupledRewardWeights)]
            check_unknown(self.reward_weights, valid, "field", "reward_weights")
            object.__setattr__(self, "reward_weights", CoupledRewardWeights(**self.reward_weights))
        elif not isinstance(self.reward_weights, CoupledRewardWeights):
            raise TypeError(
                "reward_weights must be a CoupledRewardWeights or a dict of its fields, got "
                f"{shown(self.reward_weights)}"
            )
        check_choice("action_mode", self.action_mode, ACTION_MODES, "action mode")
        if isinstance(self.torque_loop, str) and self.torque_loop not in TORQUE_LOOPS:
            names = controller_names()
            if self.torque_loop not in names:
                raise ValueError(
                    f"torque_loop = {shown(self.torque_loop)} is not a known torque loop: allowed "
                    f"{list(TORQUE_LOOPS)} or a registered controller {names}"
                )
        elif not isinstance(self.torque_loop, (str, CompiledController)):
            raise TypeError(
                "torque_loop must be 'pi', 'none', a controller name or a controller with a "
                f"compiled_law, got {shown(self.torque_loop)}"
            )
        if isinstance(self.force_loop, str) and self.force_loop not in FORCE_LOOPS:
            names = axial_controller_names()
            if self.force_loop not in names:
                raise ValueError(
                    f"force_loop = {shown(self.force_loop)} is not a known axial loop: allowed "
                    f"{list(FORCE_LOOPS)} or a registered axial controller {names}"
                )
        elif not isinstance(self.force_loop, (str, AxialController)):
            raise TypeError(
                "force_loop must be 'fixed', 'none', an axial controller name or an "
                f"AxialController, got {shown(self.force_loop)}"
            )
        check_choice("axial_input", self.axial_input, AXIAL_INPUTS, "axial input")
        check_range("hook_stiffness_n_m", self.hook_stiffness_n_m, *HOOK_STIFFNESS_RANGE_N_M)
        check_range("residual_hook_speed_m_s", self.residual_hook_speed_m_s, 0.0, 10.0)
        check_range("max_hook_speed_m_s", self.max_hook_speed_m_s, 1e-6, 10.0)
        check_choice("surface", self.surface, ("max", "delay"), "surface rule")
        if not isinstance(self.randomize, bool):
            raise TypeError(f"randomize must be True or False, got {shown(self.randomize)}")
        check_range("reference_speed_rad_s", self.reference_speed_rad_s, 0.1, 100.0)
        check_range("max_force_n", self.max_force_n, 1.0, 1e7)
        wf = self.bit_parameters.contact_force_n
        check_range("applied_force_n", self.applied_force_n, 0.0, self.max_force_n)
        require(
            "applied_force_n",
            self.applied_force_n,
            f"({wf:g}, max_force_n = {self.max_force_n:g}] N",
            self.applied_force_n > wf,
        )
        check_range("speed_loop_kp_nms_rad", self.speed_loop_kp_nms_rad, 0.0, 1e6)
        check_range("speed_loop_ki_nm_rad", self.speed_loop_ki_nm_rad, 0.0, 1e6)
        check_range("residual_torque_nm", self.residual_torque_nm, 0.0, 1e6)
        check_range("residual_force_n", self.residual_force_n, 0.0, 1e7)
        check_range("max_torque_nm", self.max_torque_nm, 1.0, 1e6)
        check_range("control_dt_s", self.control_dt_s, PLANT_STEP_S, 10.0)
        steps = self.control_dt_s / PLANT_STEP_S
        require(
            "control_dt_s",
            self.control_dt_s,
            f"a multiple of the plant step {PLANT_STEP_S:g} s",
            abs(steps - round(steps)) < 1e-6,
        )
        check_episode_s(self.episode_s, self.control_dt_s)
        if self.action_mode == "force" and self.torque_loop == "none":
            raise ValueError(
                "action_mode = 'force' needs a torque loop (torque_loop not 'none'): something "
                "must turn the string"
            )
        if self.action_mode == "torque" and self.force_loop == "none":
            raise ValueError("action_mode = 'torque' needs an axial loop (force_loop not 'none')")

    @property
    def string_parameters(self) -> DrillStringParameters:
        """The torsional string's parameters."""
        return PRESETS[self.string] if isinstance(self.string, str) else self.string

    @property
    def bit_parameters(self) -> RgdParameters:
        """The bit's parameters."""
        return RGD_PRESETS[self.bit] if isinstance(self.bit, str) else self.bit

    @property
    def substeps(self) -> int:
        """Plant steps per decision."""
        return round(self.control_dt_s / PLANT_STEP_S)


def _ring_capacity() -> int:
    """Entries of each delay line (bit angle and cut depth) a string keeps."""
    return math.ceil(_RING_SPAN / _SPACING_FRACTION) + 16


def _string_bytes() -> int:
    """Bytes of the two delay lines of one string (what bounds ``num_envs``)."""
    return 2 * 8 * _ring_capacity()


class DrillStringCoupledEnv(
    EpisodeStepsSpec, gym.Env[npt.NDArray[np.float32], npt.NDArray[np.float32]]
):
    """The paper's 4-DOF torsional drill string with an axial BHA and the regenerative bit.

    **Description.** Top drive, pipes, collars and bit of ``DrillString-v0``; the bit also
    moves axially (mass ``M``), pushed down by the applied force, and cuts the rock through the
    RGD law (depth of cut from the surface the previous blade left, wear-flat contact, stick,
    axial hold and bounce; docs/coupled-model.md). The agent trades rate of penetration
    against stick-slip, bounce and energy.

    **Action space.** ``Box(-1, 1, (k,))``, ``k = 2`` (``action_mode="both"``: torque, force)
    or 1. Torque: with the PI speed loop, ``u = clip(u_pi + a residual_torque_nm, 0,
    max_torque_nm)``; without it, ``u = (a + 1)/2 max_torque_nm``. Force: with the fixed
    base, ``W_0 = clip(applied_force_n + a residual_force_n, 0, max_force_n)``; without it,
    ``W_0 = (a + 1)/2 max_force_n``. Inputs are held over each decision.

    **Observation space.** ``Box(-50, 50, (8,), float32)``: :data:`OBSERVATION_NAMES`.

    **Reward.** :class:`CoupledRewardWeights`: rate of penetration minus bit-speed error,
    stuck and bounce fractions and top-drive power, per decision.

    **Starting state.** Steady drilling at the reference speed and the force set point (the
    rock surface of steady drilling behind the bit, the string twisted to carry the steady
    torque) with the bit speed lowered to 0.9 of it (``randomize``: U[0.8, 1.0] and the rock's
    intrinsic energy x U[0.8, 1.2], from the reset seed).

    **Episode end.** Truncated after ``episode_s`` (``env.spec.max_episode_steps`` decisions);
    terminated if the state stops being finite or a speed leaves 1000 rad/s
    (``info["termination_reason"] = "diverged"``, reward -1 as in ``DrillString-v0``; a further
    step before ``reset()`` is a ``RuntimeError``).

    **Arguments.** The fields of :class:`CoupledEnvConfig` as keywords.

    **Info** (units in the keys): ``time_s``, ``bit_speed_rad_s``, ``top_drive_speed_rad_s``,
    ``top_drive_torque_nm``, ``base_torque_nm``, ``applied_force_n``, ``wob_n`` and
    ``tob_nm`` (means over the decision), ``rop_m_s``, ``depth_m``, ``depth_of_cut_m`` (the
    depth of cut per blade ``d_n`` now: negative off the rock), ``mse_pa`` (mechanical
    specific energy so far: bit work over the rock volume cut, 0 before any cut),
    ``stuck_fraction``, ``bounce_fraction``, ``hold_fraction``, ``bit_stuck``, ``off_bottom``,
    ``top_drive_power_w``, ``reward_terms``.

    **Version history.** v0: first version.

    Example::

        import gymnasium as gym
        import drill_env
        env = gym.make("DrillStringCoupled-v0", action_mode="torque")
        obs, info = env.reset(seed=0)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    """

    metadata: dict[str, Any] = {"render_modes": list(render.RENDER_MODES), "render_fps": 20}

    def __init__(self, render_mode: str | None = None, **keywords: Any) -> None:
        render.check_render_mode(render_mode)  # first: a bad value is refused before any work
        self._spec: EnvSpec | None = None
        check_unknown(keywords, [f.name for f in dataclasses.fields(CoupledEnvConfig)])
        self.render_mode = render_mode
        with input_type_errors():
            self.config = CoupledEnvConfig(**keywords)
        c = self.config
        self.metadata = {
            "render_modes": render.available_render_modes(),
            "render_fps": 1.0 / c.control_dt_s,
        }
        self._rendering = (
            None if render_mode is None else render.EnvRendering(render_mode, 4, c.control_dt_s)
        )
        size = 2 if c.action_mode == "both" else 1
        self.action_space = gym.spaces.Box(-1.0, 1.0, (size,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(
            -OBS_LIMIT, OBS_LIMIT, (len(OBSERVATION_NAMES),), dtype=np.float32
        )
        self._string = c.string_parameters
        self._bit_nominal = c.bit_parameters
        self._steps_per_episode = round(c.episode_s / c.control_dt_s)
        capacity = _ring_capacity()
        self._ring_phi = np.zeros(capacity)
        self._ring_r = np.zeros(capacity)
        self._ring = np.zeros(3, dtype=np.int64)
        self._y = np.zeros(_N_Y)
        self._regime = np.zeros(1, dtype=np.int64)
        self._acc = np.zeros(_N_A)
        self._work = np.zeros((5, _N_Y))
        self._p = np.zeros(_N_Q)
        self._meas = np.zeros(N_MEASUREMENT)
        self._law: CompiledLaw | None = None
        if c.torque_loop not in TORQUE_LOOPS:
            controller = resolve_controller(c.torque_loop)
            if not isinstance(controller, CompiledController):
                raise TypeError(f"torque_loop = {shown(c.torque_loop)} has no compiled law")
            self._law = compile_law(controller, self._string, TorqueLimits(0.0, c.max_torque_nm))
        self._law_state = np.zeros(1) if self._law is None else self._law.initial_state.copy()
        self._law_params = np.zeros(1) if self._law is None else self._law.params
        self._axial: AxialController | None = None
        if c.force_loop not in FORCE_LOOPS:
            loop = c.force_loop
            self._axial = make_axial_controller(loop) if isinstance(loop, str) else loop
        self._ready = False
        self._running = False  # started, and the episode has not ended by diverging

    @property
    def _episode_steps(self) -> int:
        return self._steps_per_episode

    def __deepcopy__(self, memo: dict[int, Any]) -> DrillStringCoupledEnv:
        """An independent env in the same state (its arrays, loops and generator copied)."""
        twin: DrillStringCoupledEnv = copy_env_attributes(self, memo)
        return twin

    def __reduce_ex__(self, protocol: Any) -> NoReturn:
        refuse_pickling(self)

    # ------------------------------------------------------------------------------ reset
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        """Start an episode from steady drilling (see the class docstring)."""
        if isinstance(seed, np.integer):  # Gymnasium takes a Python int only
            seed = int(seed)
        super().reset(seed=seed)
        if options:
            raise ValueError(f"options = {shown(options)} is not supported: allowed None or {{}}")
        c, s = self.config, self._string
        rng = self.np_random
        rock = float(rng.uniform(0.8, 1.2)) if c.randomize else 1.0
        start = float(rng.uniform(0.8, 1.0)) if c.randomize else 0.9
        bit = dataclasses.replace(
            self._bit_nominal, intrinsic_energy_pa=self._bit_nominal.intrinsic_energy_pa * rock
        )
        self._bit = bit
        w_ref = c.reference_speed_rad_s
        steady = steady_state(bit, w_ref, c.applied_force_n)
        nominal = steady_state(self._bit_nominal, w_ref, c.applied_force_n)
        self._v_ref = nominal.rate_of_penetration_m_s
        t_bit = steady.torque_on_bit_nm + s.c_bit * w_ref
        self._u_steady = s.c_dt * w_ref + t_bit
        self._p_ref = (s.c_dt * w_ref + nominal.torque_on_bit_nm + s.c_bit * w_ref) * w_ref
        p = self._p
        p[:_N_P] = _kernel_parameters(bit, w_ref, c.applied_force_n, 0.0, c.surface)
        p[_P_I] = s.J_bi
        p[_P_CT] = s.c_bit
        p[_Q_J_DT], p[_Q_J_PI], p[_Q_J_CO] = s.J_dt, s.J_pi, s.J_co
        p[_Q_C_DT], p[_Q_C_PI], p[_Q_C_CO], p[_Q_C_BI] = s.c_dt, s.c_pi, s.c_co, s.c_bi
        p[_Q_K_PI], p[_Q_K_CO], p[_Q_K_BI] = s.k_pi, s.k_co, s.k_bi
        p[_Q_TORQUE] = self._u_steady
        hook = c.axial_input == "hook_speed"
        if hook:
            p[_P_K] = c.hook_stiffness_n_m
        self._hook_m = 0.0
        self._command = self._v_ref if hook else c.applied_force_n
        self._law_state = np.zeros(1) if self._law is None else self._law.initial_state.copy()
        self._meas[:] = 0.0
        self._meas[M_APPLIED_TORQUE] = self._u_steady
        if self._axial is not None:
            self._axial.reset(
                AxialSetup(
                    axial_input=c.axial_input,
                    force_set_point_n=c.applied_force_n,
                    rop_reference_m_s=self._v_ref,
                    min_command=-c.max_hook_speed_m_s if hook else 0.0,
                    max_command=c.max_hook_speed_m_s if hook else c.max_force_n,
                    max_torque_nm=c.max_torque_nm,
                )
            )
        y = self._y
        y[:] = 0.0
        y[_Y_V] = steady.rate_of_penetration_m_s
        y[_Y_OM] = start * w_ref
        y[_Y_PHI_CO] = t_bit / s.k_bi
        y[_Y_PHI_PI] = y[_Y_PHI_CO] + t_bit / s.k_co
        y[_Y_PHI_DT] = y[_Y_PHI_PI] + t_bit / s.k_pi
        y[_Y_OM_DT] = y[_Y_OM_PI] = y[_Y_OM_CO] = w_ref
        blade = bit.blade_angle_rad
        self._ring_phi[:] = 0.0
        self._ring_r[:] = 0.0
        self._ring_phi[0] = -3.0 * blade
        self._ring_r[0] = steady.surface_slope_m_rad * self._ring_phi[0]
        self._ring[:] = (0, 1, 0)
        self._regime[0] = _chain_initial_regime(y, p, self._ring_phi, self._ring_r, self._ring)
        self._t = 0.0
        self._integral = 0.0
        self._steps = 0
        self._totals = np.zeros(4)  # bit work J, top-drive work J, stuck s, off-rock s
        self._last = {
            "wob_n": c.applied_force_n,
            "tob_nm": steady.torque_on_bit_nm,
            "rop_m_s": steady.rate_of_penetration_m_s,
            "off": 0.0,
        }
        self._u = self._u_steady
        self._force = c.applied_force_n
        self._base = self._u_steady
        self._ready = True
        self._running = True
        if self._rendering is not None:
            self._record_frame(new_episode=True)
        return self._observation(), self._info({}, 0.0, 0.0, 0.0)

    # ------------------------------------------------------------------------------- step
    def _inputs(self, action: npt.NDArray[np.float64]) -> tuple[float, float, float, float]:
        """``(top-drive torque N m, axial command N or m/s, base torque N m, residual torque
        N m)`` for ``action``; with a compiled torque law the torque is the last one applied
        (the law sets it at every plant step, adding the residual)."""
        c = self.config
        a_torque = float(action[0]) if c.action_mode in ("both", "torque") else 0.0
        a_axial = float(action[-1]) if c.action_mode in ("both", "force") else 0.0
        residual = 0.0
        if self._law is not None:
            base = self._u
            residual = a_torque * c.residual_torque_nm
            torque = self._u
        else:
            error = c.reference_speed_rad_s - float(self._y[_Y_OM_DT])
            base = 0.0
            if c.torque_loop == "pi":
                base = (
                    self._u_steady
                    + c.speed_loop_kp_nms_rad * error
                    + c.speed_loop_ki_nm_rad * self._integral
                )
                raw = base + a_torque * c.residual_torque_nm
            else:
                raw = 0.5 * (a_torque + 1.0) * c.max_torque_nm
            torque = min(max(raw, 0.0), c.max_torque_nm)
            if c.torque_loop == "pi" and raw == torque:  # integrate only while not saturated
                self._integral += error * c.control_dt_s
        hook = c.axial_input == "hook_speed"
        scale = c.residual_hook_speed_m_s if hook else c.residual_force_n
        if self._axial is not None:
            seen = AxialMeasurement(
                wob_n=float(self._last["wob_n"]),
                rop_m_s=float(self._last["rop_m_s"]),
                surface_torque_nm=self._surface_torque(),
                top_drive_torque_nm=self._u,
                command=self._command,
            )
            command = float(self._axial.command(seen, c.control_dt_s)) + a_axial * scale
            if not math.isfinite(command):
                raise ValueError(f"the axial controller returned {shown(command)}: allowed finite")
        elif c.force_loop == "fixed":
            command = (self._v_ref if hook else c.applied_force_n) + a_axial * scale
        elif hook:
            command = a_axial * c.max_hook_speed_m_s
        else:
            command = 0.5 * (a_axial + 1.0) * c.max_force_n
        if hook:
            command = min(max(command, -c.max_hook_speed_m_s), c.max_hook_speed_m_s)
        else:
            command = min(max(command, 0.0), c.max_force_n)
        return torque, command, base, residual

    def step(
        self, action: Any
    ) -> tuple[npt.NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        """Hold the inputs over one decision and advance the plant."""
        if not self._running:
            if not self._ready:
                raise RuntimeError("call reset() before step()")
            raise RuntimeError("the episode has ended (diverged): call reset()")
        size = 2 if self.config.action_mode == "both" else 1
        a = validate_actions(action, 1, size=size)[0].reshape(size)
        c = self.config
        torque, command, base, residual = self._inputs(a)
        self._base, self._command = base, command
        self._p[_Q_TORQUE] = torque
        if c.axial_input == "hook_speed":
            # F_ax = W_0 + K (x_hook - U) with x_hook = x_k + V_top (t - t_k): in the kernel's
            # form W0' + K (V_top t - U), W0' = W_0 + K (x_k - V_top t_k).
            self._p[_P_VTOP] = command
            self._p[_P_W0] = c.applied_force_n + c.hook_stiffness_n_m * (
                self._hook_m - command * self._t
            )
        else:
            self._p[_P_W0] = command
        depth_before = float(self._y[_Y_U])
        n = c.substeps
        _chain_advance(
            self._p, self._y, self._regime, self._t, n, PLANT_STEP_S, c.reference_speed_rad_s,
            self._ring_phi, self._ring_r, self._ring, self._acc, self._work,
            0 if self._law is None else self._law.address, self._law_params, self._law_state,
            self._meas, residual, c.max_torque_nm,
        )  # fmt: skip
        acc = self._acc
        done = int(acc[_A_DONE])
        span = max(done, 1) * PLANT_STEP_S
        self._t += done * PLANT_STEP_S
        if c.axial_input == "hook_speed":
            self._hook_m += command * done * PLANT_STEP_S
        self._u = acc[_A_TORQUE] / span if done else torque
        self._force = self._applied_force()
        self._steps += 1
        diverged = done < n
        rop = (float(self._y[_Y_U]) - depth_before) / span
        stuck, off = acc[_A_STUCK] / span, acc[_A_OFF] / span
        self._last = {
            "wob_n": acc[_A_WOB] / span,
            "tob_nm": acc[_A_TOB] / span,
            "rop_m_s": rop,
            "off": off,
        }
        self._totals += (acc[_A_BIT_WORK], acc[_A_TD_WORK], acc[_A_STUCK], acc[_A_OFF])
        power = acc[_A_TD_WORK] / span
        w = c.reward_weights
        terms = {
            "rop": w.rop * rop / self._v_ref,
            "speed_error": -w.speed_error * acc[_A_SPEED_ERR] / span / c.reference_speed_rad_s,
            "stuck": -w.stuck * stuck,
            "bounce": -w.bounce * off,
            "energy": -w.energy * power / self._p_ref,
        }
        reward = float(sum(terms.values()))
        truncated = self._steps >= self._steps_per_episode and not diverged
        info = self._info(terms, stuck, off, acc[_A_HOLD] / span)
        info["top_drive_power_w"] = power
        if diverged:
            reward = DIVERGED_REWARD
            info["termination_reason"] = "diverged"
            self._running = False
        if self._rendering is not None:
            self._record_frame()
        return self._observation(), reward, diverged, truncated, info

    def _applied_force(self) -> float:
        """The axial force on the bit from above now, N (``F_ax`` without axial damping)."""
        c = self.config
        if c.axial_input == "hook_speed":
            return c.applied_force_n + c.hook_stiffness_n_m * (self._hook_m - self._y[_Y_U])
        return self._command

    # -------------------------------------------------------------------------- rendering
    def _record_frame(self, new_episode: bool = False) -> None:
        assert self._rendering is not None
        y = self._y
        state = (
            y[_Y_OM_DT], y[_Y_PHI_DT] - y[_Y_PHI_PI], y[_Y_OM_PI], y[_Y_PHI_PI] - y[_Y_PHI_CO],
            y[_Y_OM_CO], y[_Y_PHI_CO] - y[_Y_PHI], y[_Y_OM],
        )  # fmt: skip
        self._rendering.record(
            self._t,
            np.array(state),
            self._u,
            self.config.reference_speed_rad_s,
            float(self._last["wob_n"]),
            int(self._regime[0]) >= _STUCK,
            new_episode=new_episode,
        )

    def render(self) -> npt.NDArray[np.uint8] | None:
        """The frame of the last 20 s (``rgb_array``: an ``(H, W, 3)`` uint8 array; ``human``:
        shown in the window, None); without a ``render_mode``, a warning and None."""
        if self._rendering is None:
            gym.logger.warn(
                "render() without a render_mode: make the env with render_mode='rgb_array' "
                "or 'human'"
            )
            return None
        return self._rendering.render()

    def close(self) -> None:
        """Close the render window, if any."""
        if self._rendering is not None:
            self._rendering.close()
        super().close()

    # ------------------------------------------------------------------------ observation
    def _surface_torque(self) -> float:
        s, y = self._string, self._y
        return s.k_pi * (y[_Y_PHI_DT] - y[_Y_PHI_PI]) + s.c_pi * (y[_Y_OM_DT] - y[_Y_OM_PI])

    def _observation(self) -> npt.NDArray[np.float32]:
        c, y = self.config, self._y
        w_ref = c.reference_speed_rad_s
        values = [
            y[_Y_OM_DT] / w_ref,
            y[_Y_OM] / w_ref,
            self._last["wob_n"] / c.applied_force_n,
            self._last["rop_m_s"] / self._v_ref,
            self._surface_torque() / c.max_torque_nm,
            self._force / c.applied_force_n,
            self._u / c.max_torque_nm,
            self._last["off"],
        ]
        obs = np.clip(np.array(values, dtype=np.float64), -OBS_LIMIT, OBS_LIMIT)
        return obs.astype(np.float32)

    def _info(
        self, terms: dict[str, float], stuck: float, off: float, hold: float
    ) -> dict[str, Any]:
        y = self._y
        bit_work, _, stuck_s, off_s = self._totals
        depth = float(y[_Y_U])
        area = math.pi * self._bit.bit_radius_m**2
        regime = int(self._regime[0])
        cursor = int(self._ring[2])  # the lookup moves the ring's cursor: put it back
        surface = _surface(y[_Y_PHI] - self._p[_P_BLADE], self._ring_phi, self._ring_r, self._ring)
        self._ring[2] = cursor
        depth_of_cut = float(y[_Y_U] - surface)
        return {
            "time_s": self._t,
            "depth_of_cut_m": depth_of_cut,
            "bit_speed_rad_s": float(y[_Y_OM]),
            "top_drive_speed_rad_s": float(y[_Y_OM_DT]),
            "top_drive_torque_nm": self._u,
            "base_torque_nm": self._base,
            "applied_force_n": self._force,
            "hook_speed_m_s": self._command if self.config.axial_input == "hook_speed" else 0.0,
            "wob_n": float(self._last["wob_n"]),
            "tob_nm": float(self._last["tob_nm"]),
            "rop_m_s": float(self._last["rop_m_s"]),
            "depth_m": depth,
            "mse_pa": bit_work / (area * depth) if depth > 1e-9 else 0.0,
            "stuck_fraction": float(stuck),
            "bounce_fraction": float(off),
            "hold_fraction": float(hold),
            "bit_stuck": regime >= _STUCK,
            "off_bottom": regime in (_AIR, _STUCK_AIR),
            "reward_terms": dict(terms),
        }

    def episode_metrics(self) -> dict[str, float]:
        """Since the reset: ``rop_m_s`` (depth over time), ``mse_pa`` (bit work over the rock
        volume cut; 0 before any cut), ``stuck_fraction``, ``bounce_fraction``,
        ``top_drive_energy_j``, ``bit_work_j`` (work done on the rock), ``rock_volume_m3`` (the
        volume cut: bit area times depth) and ``time_s``."""
        bit_work, td_work, stuck_s, off_s = self._totals
        t = max(self._t, 1e-12)
        depth = float(self._y[_Y_U])
        area = math.pi * self._bit.bit_radius_m**2
        return {
            "time_s": self._t,
            "rop_m_s": depth / t,
            "mse_pa": bit_work / (area * depth) if depth > 1e-9 else 0.0,
            "stuck_fraction": stuck_s / t,
            "bounce_fraction": off_s / t,
            "top_drive_energy_j": float(td_work),
            "bit_work_j": float(bit_work),
            "rock_volume_m3": area * depth,
        }


class DrillStringCoupledVectorEnv(VectorEnv):
    """``num_envs`` coupled strings (``gym.make_vec("DrillStringCoupled-v0", num_envs=N)``,
    the registered ``vector_entry_point``); the keywords are those of
    :class:`DrillStringCoupledEnv`, shared by all strings.

    Each string is a :class:`DrillStringCoupledEnv` advanced by its own compiled call (one
    event-located plant per string: the regime switches of one string do not hold up the
    others). ``reset(seed=s)`` seeds string ``i`` with ``s + i``, as Gymnasium's
    ``SyncVectorEnv`` does, so string ``i`` reproduces a single env reset with ``seed=s + i``
    bit for bit. Autoreset follows Gymnasium's next-step mode: the step after an episode ends
    resets that string (reward 0, not terminated or truncated). ``infos`` hold one array per
    key with its ``_key`` mask; ``reward_terms`` is a dict of such arrays.
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        **keywords: Any,
    ) -> None:
        most = min(MAX_NUM_ENVS, MAX_BATCH_BYTES // _string_bytes())
        num_envs = check_int("num_envs", num_envs, 1, most)
        if max_episode_steps is not None:
            most_steps = round(MAX_EPISODE_S / PLANT_DT_S)  # as the other vector envs
            check_int("max_episode_steps", max_episode_steps, 1, most_steps)
        if render_mode is not None:
            raise ValueError(
                f"render_mode = {shown(render_mode)} is not supported by the vector env: allowed "
                "None (render a single env)"
            )
        self.max_episode_steps = max_episode_steps
        self.num_envs = num_envs
        first = DrillStringCoupledEnv(**keywords)
        self.envs = [first] + [
            DrillStringCoupledEnv(**{**keywords, **_copied_loops(keywords)})
            for _ in range(num_envs - 1)
        ]
        self.config = first.config
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._started = False

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        """Reset every string, or only those of ``options["reset_mask"]`` (a bool array of
        ``num_envs``, Gymnasium's partial reset); ``s`` gives string ``i`` the seed ``s + i``,
        a list one each."""
        mask = np.ones(self.num_envs, dtype=bool)
        if options and "reset_mask" in options:
            options = dict(options)
            mask = np.asarray(options.pop("reset_mask"))
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
                raise ValueError(
                    f"reset_mask must be a bool array of shape ({self.num_envs},), got {shown(mask)}"
                )
            if not self._started and not mask.all():
                raise ValueError("the first reset must reset every string (reset_mask all True)")
        if options:
            raise ValueError(
                f"options = {shown(options)} is not supported: allowed None, {{}} or a reset_mask"
            )
        seeds = check_seeds(seed, self.num_envs)
        results = []
        for i, (env, s) in enumerate(zip(self.envs, seeds, strict=True)):
            if mask[i]:
                results.append(env.reset(seed=s))
                self._needs_reset[i] = False
                self._steps[i] = 0
            else:
                results.append((env._observation(), {}))
        self._started = True
        return np.stack([r[0] for r in results]), self._batch_infos([r[1] for r in results])

    def step(
        self, actions: Any
    ) -> tuple[
        npt.NDArray[np.float32],
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
        npt.NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step every string with its row of ``actions`` ``(num_envs, k)``."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        k = self.single_action_space.shape[0]  # type: ignore[index]
        a = validate_actions(actions, self.num_envs, batched=True, size=k)[0]
        a = a.reshape(self.num_envs, k)
        observations, infos = [], []
        rewards = np.zeros(self.num_envs)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        for i, env in enumerate(self.envs):
            if self._needs_reset[i]:
                obs, info = env.reset()
                self._steps[i] = 0
            else:
                obs, reward, term, trunc, info = env.step(a[i])
                self._steps[i] += 1
                if self.max_episode_steps is not None and self._steps[i] >= self.max_episode_steps:
                    trunc = not term
                rewards[i], terminated[i], truncated[i] = float(reward), term, trunc
            observations.append(obs)
            infos.append(info)
        self._needs_reset = terminated | truncated
        return np.stack(observations), rewards, terminated, truncated, self._batch_infos(infos)

    def _batch_infos(self, infos: list[dict[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        keys = dict.fromkeys(k for info in infos for k in info if k != "reward_terms")
        for key in keys:
            present = np.array([key in info for info in infos])
            example = next(info[key] for info in infos if key in info)
            dtype = object if isinstance(example, str) else None
            values = [info.get(key, "" if dtype is object else 0) for info in infos]
            out[key] = np.array(values, dtype=dtype)
            out["_" + key] = present
        batch: dict[str, Any] = {}
        for t in (f.name for f in dataclasses.fields(CoupledRewardWeights)):
            batch[t] = np.array([info.get("reward_terms", {}).get(t, 0.0) for info in infos])
            batch["_" + t] = np.array([t in info.get("reward_terms", {}) for info in infos])
        out["reward_terms"] = batch
        out["_reward_terms"] = np.ones(self.num_envs, dtype=bool)
        return out

    def episode_metrics(self) -> list[dict[str, float]]:
        """:meth:`DrillStringCoupledEnv.episode_metrics` of every string."""
        return [env.episode_metrics() for env in self.envs]


def _copied_loops(keywords: dict[str, Any]) -> dict[str, Any]:
    """Controller objects given as loops, copied so that no two strings share one's state."""
    return {
        key: copy.deepcopy(keywords[key])
        for key in ("torque_loop", "force_loop")
        if key in keywords and not isinstance(keywords[key], str)
    }
