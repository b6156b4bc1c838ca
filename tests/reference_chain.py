"""Independent event-located reference for the distributed (chain) string (test helper).

This module re-implements the discretised field string from its written description in
``docs/distributed-string.md`` alone, with numpy and scipy only; it imports nothing from
``drill_env``. Where the package integrates the twist form with a fixed-step RK4 on contiguous
rows, this reference uses ABSOLUTE node angles and dense mass, damping and stiffness matrices,

    M phi'' + C phi' + K phi = u e_top - T_bit e_bit,

integrated by ``scipy.integrate.solve_ivp`` (DOP853, dense output) segment by segment between
the friction events, as ``tests/reference_solver.py`` does for the 4-DOF plant:

* STUCK: the bit's speed is held at exactly 0 (its acceleration is 0); the segment ends when the
  torque the string applies to the bit, ``T_e``, reaches ``+T_a`` or ``-T_a``; the bit then
  slips in the direction of ``T_e``.
* SLIP in direction ``d``: ``T_bit = d [T_0 + (T_a - T_0) exp(-xi |w_bit|)]``; the segment ends
  when the bit speed returns to 0, where the bit sticks if ``|T_e| <= T_a``, else slips in the
  direction of ``T_e``.

The stick band ``Dw`` is not used: the reference is the limit ``Dw -> 0``. Twists are the
differences of neighbouring absolute angles.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.integrate import solve_ivp

__all__ = [
    "DEEP_5000M",
    "FIELD_2500M",
    "ReferenceString",
    "Section",
    "reference_chain_matrices",
    "reference_chain_trajectory",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Section:
    """Uniform tube: length m, OD m, ID m, shear modulus Pa, density kg/m^3."""

    length: float
    od: float
    id: float
    g: float
    rho: float


@dataclass(frozen=True)
class ReferenceString:
    """Everything the reference needs, in SI units (see the module docstring)."""

    sections: Sequence[Section]  # top (drill pipe) to bottom (bit)
    j_top_drive: float  # kg m^2
    j_bit: float  # kg m^2
    bit_radius: float  # m
    mu_a: float
    mu_0: float
    xi: float  # s/rad
    mud_rate: float  # 1/s: mud torque per metre = mud_rate * rho * J * w
    kelvin_voigt_tau: float  # s: element damper = tau * element spring
    c_top_drive: float  # N m s/rad to ground at the top node
    c_bit: float  # N m s/rad to ground at the bit node
    element_length: float  # m: longest element


# Well B of Aarsnes & Shor (2018) at 2,500 m (values written out again from the description).
_BHA = [
    Section(48.70, 0.150473, 0.096207, 67e9, 7850.0),
    Section(114.80, 0.187322, 0.098912, 67e9, 7850.0),
    Section(56.70, 0.209550, 0.071438, 67e9, 7850.0),
    Section(38.88, 0.247280, 0.123391, 67e9, 7850.0),
]
FIELD_2500M = ReferenceString(
    sections=[Section(2500.0 - sum(s.length for s in _BHA), 0.146529, 0.123024, 61e9, 7850.0)]
    + _BHA,
    j_top_drive=2900.0,
    j_bit=0.5 * 50.0 * 0.108**2,
    bit_radius=0.108,
    mu_a=0.8,
    mu_0=0.5,
    xi=0.5,
    mud_rate=0.0833,
    kelvin_voigt_tau=1e-3,
    c_top_drive=425.0,
    c_bit=0.0,
    element_length=25.0,
)


# 5,000 m of API 5DP 5 in 19.5 lb/ft pipe (OD 5.000 in, wall 0.362 in), G 79.3 GPa, same BHA.
DEEP_5000M = ReferenceString(
    sections=[Section(5000.0 - sum(s.length for s in _BHA), 0.127, 4.276 * 0.0254, 79.3e9, 7850.0)]
    + _BHA,
    j_top_drive=FIELD_2500M.j_top_drive,
    j_bit=FIELD_2500M.j_bit,
    bit_radius=FIELD_2500M.bit_radius,
    mu_a=0.8,
    mu_0=0.5,
    xi=0.5,
    mud_rate=0.0833,
    kelvin_voigt_tau=1e-3,
    c_top_drive=425.0,
    c_bit=0.0,
    element_length=25.0,
)


def reference_chain_matrices(s: ReferenceString) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Mass (diagonal), damping and stiffness matrices of the lumped chain, each (n, n).

    Each section is cut into ceil(L / element_length) (at least 1) equal elements; an element
    of length l is a spring G J / l with a Kelvin-Voigt damper tau G J / l, and half of its
    inertia rho J l and of its mud damping mud_rate rho J l goes to each end node.
    """
    springs: list[float] = []
    masses: list[float] = []  # inertia carried by each element
    for sec in s.sections:
        j = math.pi * (sec.od**4 - sec.id**4) / 32.0
        count = max(1, math.ceil(sec.length / s.element_length - 1e-9))
        length = sec.length / count
        springs += [sec.g * j / length] * count
        masses += [sec.rho * j * length] * count
    n = len(springs) + 1
    m = np.zeros((n, n))
    c = np.zeros((n, n))
    k = np.zeros((n, n))
    for e, (ke, me) in enumerate(zip(springs, masses, strict=True)):
        for a in (e, e + 1):
            m[a, a] += 0.5 * me
            c[a, a] += 0.5 * s.mud_rate * me
        block = np.array([[1.0, -1.0], [-1.0, 1.0]])
        k[e : e + 2, e : e + 2] += ke * block
        c[e : e + 2, e : e + 2] += s.kelvin_voigt_tau * ke * block
    m[0, 0] += s.j_top_drive
    m[-1, -1] += s.j_bit
    c[0, 0] += s.c_top_drive
    c[-1, -1] += s.c_bit
    return m, c, k


def reference_chain_trajectory(
    s: ReferenceString,
    torque_nm: float,
    wob_n: float,
    t_end_s: float,
    t_eval_s: FloatArray,
    rtol: float = 1e-9,
    atol: float = 1e-11,
    *,
    max_step_s: float = 0.01,
    max_events: int = 10_000,
) -> tuple[FloatArray, list[tuple[float, str]]]:
    """States under a constant top-drive torque, from rest with the bit stuck.

    Args:
        s: The string.
        torque_nm: Top-drive torque, N m.
        wob_n: Weight on bit, N (> 0).
        t_end_s: End of the run, s.
        t_eval_s: Output times, s, non-decreasing within [0, t_end_s]; a time exactly at an
            event gets the post-event state.
        rtol, atol: DOP853 tolerances.
        max_step_s: Largest integrator step, s. The default 0.01 s keeps the dense output
            accurate through long slip phases, in which the string rings at up to ~200 rad/s.
        max_events: Most mode switches allowed.

    Returns:
        ``(states, segments)``: states in the interleaved twist layout
        ``(w_0, phi_0 - phi_1, w_1, ..., w_{n-1})``, shape (len(t_eval_s), 2 n - 1); and the
        (start time, mode name) of every segment.
    """
    if not wob_n > 0:
        raise ValueError(f"wob_n={wob_n!r} must be > 0")
    m, c, k = reference_chain_matrices(s)
    n = m.shape[0]
    inv_m = 1.0 / np.diag(m)
    t_a = s.mu_a * wob_n * s.bit_radius
    t_0 = s.mu_0 * wob_n * s.bit_radius
    k_last = -k[n - 2, n - 1]
    c_last = -c[n - 2, n - 1] if n > 1 else 0.0
    d_bit = c[n - 1, n - 1] - c_last  # damping of the bit node to ground

    def torque_on_bit(y: FloatArray) -> float:
        phi, w = y[:n], y[n:]
        return float(
            k_last * (phi[n - 2] - phi[n - 1]) + c_last * (w[n - 2] - w[n - 1]) - d_bit * w[n - 1]
        )

    def make_rhs(mode: int) -> Callable[[float, FloatArray], FloatArray]:
        def rhs(_t: float, y: FloatArray) -> FloatArray:
            phi, w = y[:n], y[n:]
            force = -(k @ phi) - (c @ w)
            force[0] += torque_nm
            if mode != 0:
                force[n - 1] -= mode * (t_0 + (t_a - t_0) * math.exp(-s.xi * abs(w[n - 1])))
            acc = force * inv_m
            if mode == 0:
                acc[n - 1] = 0.0
            return np.concatenate((w, acc))

        return rhs

    def make_events(mode: int) -> list[Callable[..., float]]:
        if mode == 0:

            def forward(_t: float, y: FloatArray) -> float:
                return torque_on_bit(y) - t_a

            def backward(_t: float, y: FloatArray) -> float:
                return torque_on_bit(y) + t_a

            forward.terminal = True  # type: ignore[attr-defined]
            forward.direction = 1.0  # type: ignore[attr-defined]
            backward.terminal = True  # type: ignore[attr-defined]
            backward.direction = -1.0  # type: ignore[attr-defined]
            return [forward, backward]

        def at_rest(_t: float, y: FloatArray) -> float:
            return float(y[2 * n - 1])

        at_rest.terminal = True  # type: ignore[attr-defined]
        at_rest.direction = -float(mode)  # type: ignore[attr-defined]
        return [at_rest]

    names = {0: "stuck", 1: "slip+", -1: "slip-"}
    t_eval = np.asarray(t_eval_s, dtype=np.float64)
    out = np.empty((t_eval.size, 2 * n - 1))
    filled = 0
    t = 0.0
    y = np.zeros(2 * n)
    mode = 0
    segments: list[tuple[float, str]] = []
    while True:
        sol = solve_ivp(
            make_rhs(mode), (t, t_end_s), y, method="DOP853", rtol=rtol, atol=atol,
            dense_output=True, events=make_events(mode), max_step=max_step_s,
        )  # fmt: skip
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp failed at t={t}: {sol.message}")
        t_stop = float(sol.t[-1])
        segments.append((t, names[mode]))
        last = sol.status == 0
        stop = int(np.searchsorted(t_eval, t_stop, side="right" if last else "left"))
        if stop > filled:
            ys = sol.sol(t_eval[filled:stop])  # (2n, count)
            phi, w = ys[:n], ys[n:]
            if mode == 0:
                w = w.copy()
                w[n - 1] = 0.0
            out[filled:stop, 0::2] = w.T
            out[filled:stop, 1::2] = (phi[:-1] - phi[1:]).T
            filled = stop
        if last:
            assert filled == t_eval.size, (filled, t_eval.size)
            return out, segments
        if len(segments) > max_events:
            raise RuntimeError(f"more than {max_events} events before t={t_stop}")
        y = np.array(sol.y[:, -1], dtype=np.float64)
        y[2 * n - 1] = 0.0
        t_e = torque_on_bit(y)
        if mode == 0:
            mode = 1 if t_e > 0.0 else -1
        elif abs(t_e) <= t_a:
            mode = 0
        else:
            mode = 1 if t_e > 0.0 else -1
        t = t_stop
