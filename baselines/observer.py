"""A state observer for controllers that need the string's state but measure only what a rig
measures: a steady-state Kalman filter on the controller's own model of the string, with the
unknown bit-rock torque as a random-walk disturbance and the delayed bit-speed telemetry
folded in at the instant it was sampled. docs/observer.md explains the design.

Everything that needs linear algebra is computed here in numpy when a law's parameters are
packed (:func:`design_observer`, :func:`pack_observer`); the compiled part,
:func:`observer_update`, runs inside the plant loop at every plant step and does a few small
matrix-vector products.

**Model.** The controller's model as a linear chain (:func:`drill_env.distributed.
chain_from_parameters`: the 4-DOF model is a chain of 4 nodes, a distributed string its
discretised chain), reduced to its lowest ``modes`` undamped modes (every mode of the 4-DOF
chain: no reduction). State ``z``: the elastic modal coordinates, the modal rates (the first
is the rigid rotation) and the bit-rock torque ``d`` (N m), ``2 m`` entries. Input: the torque
the drive applied over the last plant step (``drill_env.layout.M_APPLIED_TORQUE``).
Measurements at every plant step: the held top-drive speed and surface torque; when a new
value arrives, the bit speed by telemetry, sampled ``D`` plant steps before.

**Outputs.** The estimate of the 4-DOF state ``x1..x7`` at the controller's probe nodes (for
a distributed string those of :func:`drill_env.modes.probe_nodes`, the coordinates the env
reports as its 4-DOF state) and of ``d``.

The filter runs in coordinates whose first eight entries are these outputs
(:func:`design_observer` transforms it), so the estimate is the filter state itself.

Parameter block (``OP_*``, from an offset ``base`` in the law's parameter vector): a header,
then ``F`` (nz, nz) and ``K`` (nz, 2) stored by columns, ``g`` (nz,), ``v_D`` (nz,) and ``V``
(J, nz) by rows. State block (``OS_*``, from an offset in the law's state vector): the step
counter, the last telemetry sample used, the count of telemetry values not used, ``z`` (its
first eight entries the estimate ``x1..x7, d``), a scratch vector and the ring buffer of
``cap`` snapshots ``(sample step, z)``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
from numba import njit

from baselines.base import Gains, Model
from drill_env.distributed import DistributedStringParameters, chain_from_parameters
from drill_env.layout import (
    M_APPLIED_TORQUE,
    M_SURFACE_TORQUE,
    M_TELEMETRY_AGE,
    M_TELEMETRY_BIT_SPEED,
    M_TOP_DRIVE_SPEED,
    N_STATE,
    X_BIT_SPEED,
)
from drill_env.modes import probe_nodes
from drill_env.parameters import PLANT_DT_S
from drill_env.sensors import MeasurementChannel

__all__ = [
    "N_OBSERVER_OUTPUTS",
    "OS_BIT_TORQUE",
    "OS_ESTIMATE",
    "OS_SKIPPED",
    "ObserverDesign",
    "ObserverGains",
    "ObserverModel",
    "design_observer",
    "discrete_filter_riccati",
    "discretize",
    "expm",
    "initial_observer_state",
    "observer_model",
    "observer_params_size",
    "observer_state_size",
    "observer_update",
    "pack_observer",
]

FloatArray = npt.NDArray[np.float64]

N_MEASURED: Final = 2  # the top-drive speed and the surface torque
MAX_IN_FLIGHT: Final = 1000
"""Most telemetry values in flight at once (``delay // period``) an observer keeps snapshots
for."""
N_OBSERVER_OUTPUTS: Final = N_STATE + 1  # x1..x7 and the bit-rock torque

# Parameter block header.
OP_NZ, OP_PERIOD, OP_DELAY, OP_CAP, OP_J = 0, 1, 2, 3, 4
OP_HEADER: Final = 5
# State block.
OS_STEP: Final = 0  # plant steps seen (the law is called once per plant step)
OS_LAST_SAMPLE: Final = 1  # plant step of the last telemetry sample taken in (-1: none)
OS_SKIPPED: Final = 2  # telemetry values not used (their delay or instant not as designed)
OS_Z: Final = 3  # the filter state z (nz), then a scratch vector (nz), then the snapshots
# The filter runs in coordinates whose first entries are its outputs:
OS_ESTIMATE: Final = OS_Z  # x1..x7: the estimated 4-DOF state, rad/s and rad
OS_BIT_TORQUE: Final = OS_ESTIMATE + N_STATE  # the estimated bit-rock torque, N m


@dataclass(frozen=True)
class ObserverGains(Gains):
    """Design choices of the state observer (docs/observer.md).

    Attributes:
        modes: Undamped modes of the model's chain kept (>= 2; a 4-DOF model has 4 and keeps
            them all).
        bit_torque_walk_nm: Random-walk intensity of the unknown bit-rock torque, N m per
            sqrt(s) (> 0): its standard deviation grows by this much in one second.
        string_torque_noise_nm: Intensity of an unknown torque spread over the string in
            proportion to its inertia (mud and bearing damping not known, unmodelled modes),
            N m sqrt(s) (>= 0).
        speed_noise_floor_rad_s: Least standard deviation assumed for the measured top-drive
            speed, rad/s (> 0).
        torque_noise_floor_nm: Least standard deviation assumed for the measured surface
            torque, N m (> 0).
        telemetry_noise_floor_rad_s: Least standard deviation assumed for the telemetry's bit
            speed, rad/s (> 0).
    """

    modes: int = 8
    bit_torque_walk_nm: float = 500.0
    string_torque_noise_nm: float = 1000.0
    speed_noise_floor_rad_s: float = 0.01
    torque_noise_floor_nm: float = 100.0
    telemetry_noise_floor_rad_s: float = 0.05

    def __post_init__(self) -> None:
        self._check_finite()
        modes_ok = isinstance(self.modes, int) and not isinstance(self.modes, bool)
        self._check("modes", "an integer >= 2", modes_ok and self.modes >= 2)
        self._check("bit_torque_walk_nm", "> 0", self.bit_torque_walk_nm > 0)
        self._check("string_torque_noise_nm", ">= 0", self.string_torque_noise_nm >= 0)
        self._check("speed_noise_floor_rad_s", "> 0", self.speed_noise_floor_rad_s > 0)
        self._check("torque_noise_floor_nm", "> 0", self.torque_noise_floor_nm > 0)
        self._check("telemetry_noise_floor_rad_s", "> 0", self.telemetry_noise_floor_rad_s > 0)


# ------------------------------------------------------------------------- linear algebra
def expm(a: npt.ArrayLike) -> FloatArray:
    """Matrix exponential of a square matrix by scaling and squaring of its Taylor series
    (the scaled matrix has norm <= 1/2, the series is summed to machine precision)."""
    m = np.array(a, dtype=np.float64)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ValueError(f"expm needs a square matrix, got shape {m.shape}")
    norm = float(np.abs(m).sum(axis=1).max()) if m.size else 0.0
    squarings = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    m /= 2.0**squarings
    result = np.eye(m.shape[0])
    term = np.eye(m.shape[0])
    for k in range(1, 40):
        term = term @ m / k
        result += term
        if np.abs(term).max() <= 1e-17 * np.abs(result).max():
            break
    for _ in range(squarings):
        result = result @ result
    return result


def discretize(
    a: npt.ArrayLike, b: npt.ArrayLike, qc: npt.ArrayLike, dt_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Exact discretisation of ``z' = A z + B u + w`` (``w`` white, intensity ``Qc``) for an
    input held over ``dt_s``: ``(Phi, Gamma, Qd)`` with ``Phi = exp(A dt)``,
    ``Gamma = int_0^dt exp(A s) ds B`` and ``Qd = int_0^dt exp(A s) Qc exp(A s)' ds`` (Van
    Loan 1978)."""
    a = np.asarray(a, dtype=np.float64)
    n = a.shape[0]
    b = np.asarray(b, dtype=np.float64).reshape(n, -1)
    augmented = np.zeros((n + b.shape[1], n + b.shape[1]))
    augmented[:n, :n] = a
    augmented[:n, n:] = b
    e = expm(augmented * dt_s)
    phi, gamma = e[:n, :n], e[:n, n:]
    van_loan = np.zeros((2 * n, 2 * n))
    van_loan[:n, :n] = -a
    van_loan[:n, n:] = np.asarray(qc, dtype=np.float64)
    van_loan[n:, n:] = a.T
    v = expm(van_loan * dt_s)
    qd = v[n:, n:].T @ v[:n, n:]
    return phi, gamma, 0.5 * (qd + qd.T)


def discrete_filter_riccati(
    phi: npt.ArrayLike, c: npt.ArrayLike, q: npt.ArrayLike, r: npt.ArrayLike
) -> FloatArray:
    """The stabilising solution ``P`` of the filter's discrete algebraic Riccati equation
    ``P = Phi P Phi' - Phi P C' (C P C' + R)^-1 C P Phi' + Q`` (the steady-state prediction
    covariance), by the structure-preserving doubling algorithm (Chu et al. 2004), which
    converges quadratically.

    Raises:
        RuntimeError: when the iteration does not converge (no stabilising solution).
    """
    a = np.asarray(phi, dtype=np.float64).T
    c = np.asarray(c, dtype=np.float64)
    g = c.T @ np.linalg.solve(np.asarray(r, dtype=np.float64), c)
    h = np.asarray(q, dtype=np.float64).copy()
    n = a.shape[0]
    eye = np.eye(n)
    for _ in range(200):
        w = np.linalg.solve(eye + g @ h, np.hstack([a, g]))
        wa, wg = w[:, :n], w[:, n:]
        h_next = h + a.T @ h @ wa
        g = g + a @ wg @ a.T
        a = a @ wa
        g = 0.5 * (g + g.T)
        h_next = 0.5 * (h_next + h_next.T)
        converged = np.abs(h_next - h).max() <= 1e-14 * max(1.0, float(np.abs(h_next).max()))
        h = h_next
        if converged:
            return h
    raise RuntimeError("the filter Riccati equation did not converge")


def _power_and_sum(f: FloatArray, w: FloatArray, steps: int) -> tuple[FloatArray, FloatArray]:
    """``(F^N, sum_{i<N} F^i W F^i')`` for ``N = steps`` by doubling."""
    n = f.shape[0]
    power, total = np.eye(n), np.zeros((n, n))  # the result so far: N = 0
    base_f, base_w = f.copy(), w.copy()  # 2^j steps
    remaining = steps
    while remaining:
        if remaining & 1:  # append 2^j steps to those done
            total = base_f @ total @ base_f.T + base_w
            power = base_f @ power
        base_w = base_f @ base_w @ base_f.T + base_w
        base_f = base_f @ base_f
        remaining >>= 1
    return power, total


# ---------------------------------------------------------------------------------- model
@dataclass(frozen=True, eq=False)
class ObserverModel:
    """The observer's continuous-time model ``z' = A z + B u + w``, ``y = C z``, and its
    outputs ``(x1..x7, d) = outputs z``.

    Attributes:
        A: (nz, nz), 1/s.
        B: (nz,): the entry of the top-drive torque (N m).
        C: (2, nz): the measured top-drive speed (rad/s) and surface torque (N m).
        outputs: (8, nz): the probe state x1..x7 (rad/s, rad) and the bit-rock torque (N m).
        force: (nz, n_nodes): the entry of a torque at each node (for the process noise).
        node_inertia_kg_m2: (n_nodes,).
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    outputs: FloatArray
    force: FloatArray
    node_inertia_kg_m2: FloatArray


def _probes(model: Model) -> tuple[int, int, int, int]:
    if isinstance(model, DistributedStringParameters):
        return probe_nodes(model)
    return (0, 1, 2, 3)


def observer_model(model: Model, modes: int) -> ObserverModel:
    """The linear chain of ``model`` in its lowest ``modes`` modes (all of them when it has
    fewer), with the bit-rock torque ``d`` as a state that drives the bit node."""
    chain = chain_from_parameters(model)
    n = chain.n_nodes
    inertia = chain.node_inertia_kg_m2.astype(np.float64)
    k = np.zeros((n, n))
    c = np.diag(chain.node_damping_nm_s_rad.astype(np.float64))
    pair = np.array([[1.0, -1.0], [-1.0, 1.0]])
    for e in range(n - 1):
        k[e : e + 2, e : e + 2] += chain.element_stiffness_nm_rad[e] * pair
        c[e : e + 2, e : e + 2] += chain.element_damping_nm_s_rad[e] * pair
    scale = 1.0 / np.sqrt(inertia)
    w2, v = np.linalg.eigh(k * scale[:, None] * scale[None, :])
    m = min(int(modes), n)
    shapes = v[:, :m] * scale[:, None]  # mass-normalised: shapes' M shapes = I
    w2 = np.maximum(w2[:m], 0.0)
    w2[0] = 0.0  # the rigid rotation (a free-free chain)
    ne = m - 1
    nz = ne + m + 1
    positions, rates, d = slice(0, ne), slice(ne, ne + m), nz - 1
    a = np.zeros((nz, nz))
    a[positions, ne + 1 : ne + m] = np.eye(ne)
    a[rates, positions] = -np.diag(w2)[:, 1:]
    a[rates, rates] = -shapes.T @ c @ shapes
    a[rates, d] = -shapes[n - 1, :]
    force = np.zeros((nz, n))
    force[rates, :] = shapes.T
    b = force[:, 0].copy()

    def speed(node: int) -> FloatArray:
        row = np.zeros(nz)
        row[rates] = shapes[node]
        return row

    def twist(upper: int, lower: int) -> FloatArray:
        row = np.zeros(nz)
        row[positions] = shapes[upper, 1:] - shapes[lower, 1:]
        return row

    k0, c0 = chain.element_stiffness_nm_rad[0], chain.element_damping_nm_s_rad[0]
    surface = k0 * twist(0, 1) + c0 * (speed(0) - speed(1))
    p0, p1, p2, p3 = _probes(model)
    bit_torque = np.zeros(nz)
    bit_torque[d] = 1.0
    out = np.vstack(
        [
            speed(p0), twist(p0, p1), speed(p1), twist(p1, p2), speed(p2), twist(p2, p3),
            speed(p3), bit_torque,
        ]
    )  # fmt: skip
    return ObserverModel(a, b, np.vstack([speed(0), surface]), out, force, inertia)


# --------------------------------------------------------------------------------- design
@dataclass(frozen=True, eq=False)
class ObserverDesign:
    """The numbers the compiled observer runs with.

    Attributes:
        F: ``(I - K C) Phi``, (nz, nz): the filter's transition over one plant step.
        g: ``(I - K C) Gamma``, (nz,): the applied torque's entry, per N m.
        K: The steady-state gain of the surface measurements, (nz, 2).
        outputs: The outputs (x1..x7, d) of the filter state, (8, nz).
        telemetry_gain: The gain of a telemetry value at its sample instant, (nz,) (zeros
            without telemetry).
        v_delay: ``F^D telemetry_gain``: its correction when it arrives D steps later, (nz,).
        v_flight: ``F^(j P) telemetry_gain``, j = 1..J: its correction of the snapshots taken
            after its sample, (J, nz).
        period_steps, delay_steps: The telemetry's period and delay in plant steps (0: none).
        capacity: Snapshots kept (``D // P + 1``; 0 without telemetry).
        prediction_covariance: The steady-state covariance of the prediction, (nz, nz).
        sample_covariance: The periodic covariance at a telemetry sample instant before its
            value is used, (nz, nz) (the filtered steady state without telemetry).
        coordinates: ``T``, (nz, nz): the filter state is ``T`` times the state of
            :func:`observer_model` (the identity until :func:`design_observer` moves the
            filter to output coordinates).
    """

    F: FloatArray
    g: FloatArray
    K: FloatArray
    outputs: FloatArray
    telemetry_gain: FloatArray
    v_delay: FloatArray
    v_flight: FloatArray
    period_steps: int
    delay_steps: int
    capacity: int
    prediction_covariance: FloatArray
    sample_covariance: FloatArray
    coordinates: FloatArray | None = None

    @property
    def nz(self) -> int:
        """Size of the filter state."""
        return int(self.F.shape[0])


def _steps(seconds: float, dt_s: float) -> int:
    return round(seconds / dt_s)


@functools.lru_cache(maxsize=64)
def design_observer(
    model: Model, channel: MeasurementChannel, gains: ObserverGains, dt_s: float = PLANT_DT_S
) -> ObserverDesign:
    """The steady-state Kalman filter of docs/observer.md for ``model``, the measurement
    ``channel`` (its sampling period and noise levels) and the design choices ``gains``.

    Covariances: process noise ``bit_torque_walk_nm^2`` on ``d'`` and a torque of intensity
    ``string_torque_noise_nm^2`` spread over the nodes in proportion to their inertia;
    measurement noise the channel's standard deviations (floored), times the number of plant
    steps a surface sample is held (a held sample is one measurement, not several).
    """
    om = observer_model(model, gains.modes)
    nz = om.A.shape[0]
    share = om.node_inertia_kg_m2 / om.node_inertia_kg_m2.sum()
    qc = gains.string_torque_noise_nm**2 * (om.force * share[None, :]) @ om.force.T
    qc[-1, -1] += gains.bit_torque_walk_nm**2
    phi, gamma, qd = discretize(om.A, om.B, qc, dt_s)
    hold = max(1, _steps(channel.sensor_period_s, dt_s))
    r = np.diag(
        [
            hold * max(channel.speed_noise_std_rad_s, gains.speed_noise_floor_rad_s) ** 2,
            hold * max(channel.torque_noise_std_nm, gains.torque_noise_floor_nm) ** 2,
        ]
    )
    p = discrete_filter_riccati(phi, om.C, qd, r)
    k = p @ om.C.T @ np.linalg.inv(om.C @ p @ om.C.T + r)
    closed = np.eye(nz) - k @ om.C
    f = closed @ phi
    g = closed @ gamma[:, 0]
    filtered = closed @ p
    filtered = 0.5 * (filtered + filtered.T)
    zero = np.zeros(nz)
    if channel.telemetry_period_s is None:
        return _in_output_coordinates(
            ObserverDesign(f, g, k, om.outputs, zero, zero, np.zeros((0, nz)), 0, 0, 0, p, filtered)
        )
    period = _steps(channel.telemetry_period_s, dt_s)
    delay = _steps(channel.telemetry_delay_s, dt_s)
    r_t = max(channel.telemetry_noise_std_rad_s, gains.telemetry_noise_floor_rad_s) ** 2
    h = om.outputs[X_BIT_SPEED]
    w = closed @ qd @ closed.T + k @ r @ k.T  # the fixed-gain filter's error noise per step
    # From one sample instant to the next the error evolves as e <- F^P e + (noise of
    # covariance S_P): the covariance before a telemetry value is the prediction covariance of
    # the filter of that P-step system measuring h z, the solution of its Riccati equation.
    f_period, w_period = _power_and_sum(f, w, period)
    sigma = discrete_filter_riccati(f_period, h[None, :], w_period, np.array([[r_t]]))
    gain = sigma @ h / (h @ sigma @ h + r_t)
    v_delay = _power_and_sum(f, w, delay)[0] @ gain
    flights = delay // period
    if flights > MAX_IN_FLIGHT:
        raise ValueError(
            f"telemetry_delay_s / telemetry_period_s = {flights} values in flight is out of "
            f"range for the observer: allowed at most {MAX_IN_FLIGHT}"
        )
    v_flight = np.zeros((flights, nz))
    v = gain
    for j in range(flights):  # F^((j + 1) P) gain
        v = f_period @ v
        v_flight[j] = v
    return _in_output_coordinates(
        ObserverDesign(
            f, g, k, om.outputs, gain, v_delay, v_flight, period, delay, flights + 1, p, sigma
        )
    )


def _in_output_coordinates(design: ObserverDesign) -> ObserverDesign:
    """The same filter in the coordinates ``T z`` whose first eight entries are the outputs
    (``T``: the output rows, then an orthonormal basis of their null space): the estimate is
    then the filter state itself, with nothing to compute at every step."""
    outputs = design.outputs
    basis = np.linalg.svd(outputs)[2][outputs.shape[0] :]  # rows spanning the null space
    t = np.vstack([outputs, basis])
    t_inv = np.linalg.inv(t)
    return dataclasses.replace(
        design,
        F=t @ design.F @ t_inv,
        g=t @ design.g,
        K=t @ design.K,
        outputs=np.eye(outputs.shape[0], design.nz),
        telemetry_gain=t @ design.telemetry_gain,
        v_delay=t @ design.v_delay,
        v_flight=design.v_flight @ t.T,
        prediction_covariance=t @ design.prediction_covariance @ t.T,
        sample_covariance=t @ design.sample_covariance @ t.T,
        coordinates=t,
    )


def observer_params_size(design: ObserverDesign) -> int:
    """Length of the observer's parameter block."""
    nz = design.nz
    return OP_HEADER + nz * nz + nz + N_MEASURED * nz + nz + design.v_flight.shape[0] * nz


def observer_state_size(design: ObserverDesign) -> int:
    """Length of the observer's state block."""
    return OS_Z + 2 * design.nz + design.capacity * (1 + design.nz)


def _check_output_coordinates(design: ObserverDesign) -> None:
    if not np.array_equal(design.outputs, np.eye(N_OBSERVER_OUTPUTS, design.nz)):
        raise ValueError("the compiled observer needs a design in output coordinates")


def pack_observer(design: ObserverDesign) -> FloatArray:
    """The observer's parameter block (``OP_*``), float64."""
    header = np.zeros(OP_HEADER)
    header[OP_NZ] = design.nz
    header[OP_PERIOD] = design.period_steps
    header[OP_DELAY] = design.delay_steps
    header[OP_CAP] = design.capacity
    header[OP_J] = design.v_flight.shape[0]
    _check_output_coordinates(design)
    block = np.concatenate(
        [
            header, design.F.T.ravel(), design.g, design.K.T.ravel(), design.v_delay,
            design.v_flight.ravel(),
        ]
    )  # fmt: skip
    assert block.size == observer_params_size(design)
    return block


def initial_observer_state(design: ObserverDesign) -> FloatArray:
    """The observer's state block at the start of an episode: the string at rest, no
    telemetry used, no snapshot."""
    _check_output_coordinates(design)
    state = np.zeros(observer_state_size(design))
    state[OS_LAST_SAMPLE] = -1.0
    ring = OS_Z + 2 * design.nz
    state[ring :: 1 + design.nz] = -1.0
    return state


# ------------------------------------------------------------------------------ compiled
@njit(cache=True)
def _use_telemetry(lp, ls, sbase, m, k, sample, nz, period, delay, cap, flights, o_vd, o_vj,
                   z, ring) -> None:  # fmt: skip
    """Fold in the telemetry value of plant step ``sample`` that arrived at step ``k``: its
    innovation against the snapshot of that instant, the correction of the current estimate
    and of the snapshots taken since, each through the filter's transition over the steps
    between. A value whose delay or instant the design does not know is counted, not used."""
    slot = ring + ((sample // period) % cap) * (1 + nz) if sample >= 0 else -1
    if k - sample != delay or sample % period != 0 or slot < 0 or ls[slot] != sample:
        ls[sbase + OS_SKIPPED] += 1.0
        return
    innovation = m[M_TELEMETRY_BIT_SPEED] - ls[slot + 1 + X_BIT_SPEED]  # z starts with x1..x7
    for j in range(nz):
        ls[z + j] += lp[o_vd + j] * innovation
    for f in range(1, flights + 1):  # the snapshot taken f periods after the sample
        later = sample + f * period
        if later > k:
            break
        other = ring + ((later // period) % cap) * (1 + nz)
        if ls[other] != later:
            continue
        v = o_vj + (f - 1) * nz
        for j in range(nz):
            ls[other + 1 + j] += lp[v + j] * innovation


@njit(cache=True)
def observer_update(lp, base: int, ls, sbase: int, m, dt: float) -> None:
    """One plant step of the observer whose parameter block starts at ``lp[base]`` and state
    block at ``ls[sbase]``, reading the measurement vector ``m`` (``drill_env.layout.M_*``)
    at a plant step of ``dt`` seconds: predict with the torque applied over the last step and
    correct with the held surface samples; keep a snapshot at a telemetry sample instant; fold
    in a telemetry value that has just arrived at the instant it was sampled. The filter runs
    in output coordinates: the estimate ``x1..x7, d`` is ``ls[sbase + OS_ESTIMATE:]``."""
    nz = int(lp[base + OP_NZ])
    period = int(lp[base + OP_PERIOD])
    delay = int(lp[base + OP_DELAY])
    cap = int(lp[base + OP_CAP])
    flights = int(lp[base + OP_J])
    o_f = base + OP_HEADER
    o_g = o_f + nz * nz
    o_k = o_g + nz
    o_vd = o_k + N_MEASURED * nz
    o_vj = o_vd + nz
    z = sbase + OS_Z
    tmp = z + nz
    ring = tmp + nz
    u = m[M_APPLIED_TORQUE]
    y0 = m[M_TOP_DRIVE_SPEED]
    y1 = m[M_SURFACE_TORQUE]
    for i in range(nz):  # z <- F z + g u + K y, column by column (F, K stored by columns)
        ls[tmp + i] = lp[o_g + i] * u + lp[o_k + i] * y0 + lp[o_k + nz + i] * y1
    for j in range(nz):
        zj = ls[z + j]
        column = o_f + j * nz
        for i in range(nz):
            ls[tmp + i] += lp[column + i] * zj
    for i in range(nz):
        ls[z + i] = ls[tmp + i]
    k = int(ls[sbase + OS_STEP])
    ls[sbase + OS_STEP] = k + 1
    if period > 0:
        if k % period == 0:  # a telemetry sample instant: keep the estimate
            slot = ring + ((k // period) % cap) * (1 + nz)
            ls[slot] = k
            for j in range(nz):
                ls[slot + 1 + j] = ls[z + j]
        age = m[M_TELEMETRY_AGE]
        if not math.isnan(age):
            sample = k - int(round(age / dt))
            if sample != ls[sbase + OS_LAST_SAMPLE]:
                ls[sbase + OS_LAST_SAMPLE] = sample
                _use_telemetry(lp, ls, sbase, m, k, sample, nz, period, delay, cap, flights,
                               o_vd, o_vj, z, ring)  # fmt: skip
