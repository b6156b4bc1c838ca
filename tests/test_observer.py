"""The state observer of the sliding-mode controllers (docs/observer.md): its numerics against
scipy, its model against the plant's own equations, the delayed telemetry against the filter
re-run from the sample instant, its accuracy in both envs, the closed loop, and that the law
sees only what is measured."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

import drill_env  # noqa: F401  (registers the envs)
from baselines import ProposedASMC, make_controller
from baselines.observer import (
    OS_ESTIMATE,
    OS_SKIPPED,
    ObserverGains,
    design_observer,
    discrete_filter_riccati,
    discretize,
    expm,
    initial_observer_state,
    observer_model,
    observer_update,
    pack_observer,
)
from baselines.smc import N_SMC_PARAMS, S_OBSERVER, SMC_PARAMS_SIZE
from drill_env.chain import chain_derivative, chain_parameter_vector
from drill_env.control import CompiledLaw, compile_law
from drill_env.distributed import chain_from_parameters, resolve_plant, with_measured_depth
from drill_env.dynamics import state_derivative
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.layout import (
    M_APPLIED_TORQUE,
    M_SURFACE_TORQUE,
    M_TELEMETRY_AGE,
    M_TELEMETRY_BIT_SPEED,
    M_TOP_DRIVE_SPEED,
    N_MEASUREMENT,
    REC_BASE_TORQUE,
    REC_REFERENCE,
    REC_SURFACE_TORQUE,
    REC_TORQUE,
    REC_X0,
    STATE_NAMES,
    X_BIT_SPEED,
)
from drill_env.modes import probe_nodes
from drill_env.parameters import PLANT_DT_S, resolve_parameters
from drill_env.sensors import MeasurementChannel

ZRIBI = resolve_parameters("zribi2024")
DT = PLANT_DT_S
QUIET = {"noise_std_rad_s": 0.0, "torque_noise_std_nm": 0.0, "telemetry_noise_std_rad_s": 0.0}


def channel(**changes: Any) -> MeasurementChannel:
    """A surface channel sampled every plant step, no noise, no telemetry, with ``changes``."""
    values: dict[str, Any] = {
        "observation": "surface",
        "speed_noise_std_rad_s": 0.0,
        "torque_noise_std_nm": 0.0,
    }
    return MeasurementChannel(**{**values, **changes})


# ------------------------------------------------------------------------ linear algebra
@pytest.mark.parametrize("scale", [1e-4, 1.0, 5.0])
def test_expm_matches_scipy(scale: float) -> None:
    a = np.random.default_rng(0).standard_normal((9, 9)) * scale
    reference = scipy.linalg.expm(a)
    np.testing.assert_allclose(expm(a), reference, rtol=1e-10, atol=1e-13 * abs(reference).max())


def test_expm_of_a_stiff_string_matches_scipy() -> None:
    """The field string's model over one plant step: fast BHA modes and a slow rotation."""
    a = observer_model(resolve_plant("field_2500m"), 16).A * DT
    np.testing.assert_allclose(expm(a), scipy.linalg.expm(a), rtol=1e-11, atol=1e-14)


def test_discretize_matches_the_integrals() -> None:
    """Gamma = int exp(A s) ds B and Qd = int exp(A s) Qc exp(A s)' ds by adaptive quadrature."""
    model = observer_model(ZRIBI, 4)
    rng = np.random.default_rng(1)
    g = rng.standard_normal((model.A.shape[0], 3))
    qc = g @ g.T
    dt = 0.01
    phi, gamma, qd = discretize(model.A, model.B, qc, dt)

    def flow(s: float) -> np.ndarray:
        return scipy.linalg.expm(model.A * s)

    gamma_ref = scipy.integrate.quad_vec(lambda s: flow(s) @ model.B, 0.0, dt, epsabs=1e-15)[0]
    qd_ref = scipy.integrate.quad_vec(lambda s: flow(s) @ qc @ flow(s).T, 0.0, dt, epsabs=1e-15)[0]
    np.testing.assert_allclose(phi, scipy.linalg.expm(model.A * dt), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(gamma[:, 0], gamma_ref, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(qd, qd_ref, rtol=1e-9, atol=1e-12 * abs(qd_ref).max())


def test_riccati_matches_scipy() -> None:
    model = observer_model(resolve_plant("field_2500m"), 8)
    qc = np.zeros_like(model.A)
    qc[-1, -1] = 500.0**2
    qc += 1e2 * model.force @ model.force.T
    phi, _, qd = discretize(model.A, model.B, qc, DT)
    r = np.diag([0.05**2, 250.0**2])
    p = discrete_filter_riccati(phi, model.C, qd, r)
    reference = scipy.linalg.solve_discrete_are(phi.T, model.C.T, qd, r)
    np.testing.assert_allclose(p, reference, rtol=1e-7, atol=1e-10 * abs(reference).max())
    gain = phi @ p @ model.C.T @ np.linalg.inv(model.C @ p @ model.C.T + r)
    residual = phi @ p @ phi.T - gain @ model.C @ p @ phi.T + qd - p
    assert abs(residual).max() < 1e-14 * abs(p).max()


def test_telemetry_gain_is_the_periodic_steady_state() -> None:
    """Iterating the fixed-gain filter's error covariance step by step, with the telemetry's
    optimal update at every sample instant, converges to the design's sample covariance and
    gain."""
    gains = ObserverGains()
    ch = channel(
        speed_noise_std_rad_s=0.1, torque_noise_std_nm=200.0, telemetry_period_s=0.02,
        telemetry_delay_s=0.03, telemetry_noise_std_rad_s=0.1,
    )  # fmt: skip
    design = design_observer(ZRIBI, ch, gains)
    model = observer_model(ZRIBI, gains.modes)
    share = model.node_inertia_kg_m2 / model.node_inertia_kg_m2.sum()
    qc = gains.string_torque_noise_nm**2 * (model.force * share) @ model.force.T
    qc[-1, -1] += gains.bit_torque_walk_nm**2
    _, _, qd = discretize(model.A, model.B, qc, DT)
    r = np.diag([0.1**2, 200.0**2])  # the channel's noise (above the floors), every step
    t = design.coordinates  # the filter runs in output coordinates T z
    assert t is not None
    np.testing.assert_allclose(design.outputs @ t, model.outputs, atol=1e-12)
    qd = t @ qd @ t.T
    closed = np.eye(design.nz) - design.K @ model.C @ np.linalg.inv(t)
    w = closed @ qd @ closed.T + design.K @ r @ design.K.T
    h = design.outputs[X_BIT_SPEED]
    r_t = 0.1**2
    sigma = np.zeros((design.nz, design.nz))
    for _ in range(3000):  # periods: the slowest closed-loop mode has forgotten its start
        gain = sigma @ h / (h @ sigma @ h + r_t)
        sigma = sigma - np.outer(gain, h @ sigma)
        for _ in range(20):
            sigma = design.F @ sigma @ design.F.T + w
    np.testing.assert_allclose(design.sample_covariance, sigma, rtol=1e-6)
    np.testing.assert_allclose(design.telemetry_gain, sigma @ h / (h @ sigma @ h + r_t), rtol=1e-6)


# ---------------------------------------------------------------------------------- model
def test_four_dof_model_is_the_plant_equations() -> None:
    """Mapped to x1..x7, the 4-DOF observer model's derivative is the plant's
    (drill_env.dynamics) with the bit slipping and d its friction torque; its measurements
    are x1 and the top spring's torque."""
    model = observer_model(ZRIBI, 8)
    assert model.A.shape == (8, 8)
    rng = np.random.default_rng(2)
    wob = 97_347.0
    t_a, t_0 = ZRIBI.static_torque_nm(wob), ZRIBI.sliding_torque_nm(wob)
    to_state = model.outputs[:7, :7]
    for _ in range(5):
        x = rng.uniform(-3.0, 3.0, 7)
        x[6] = rng.uniform(2.0, 15.0)  # slipping forwards
        u = rng.uniform(0.0, 2e4)
        d = t_0 + (t_a - t_0) * math.exp(-ZRIBI.xi * x[6])
        z = np.append(np.linalg.solve(to_state, x), d)
        np.testing.assert_allclose(model.outputs[:7] @ z, x, atol=1e-12)
        derivative = model.outputs[:7] @ (model.A @ z + model.B * u)
        reference = state_derivative(x, u, ZRIBI, wob, bit_stuck=False)
        np.testing.assert_allclose(derivative, reference, rtol=1e-9, atol=1e-9)
        surface = ZRIBI.k_pi * x[1] + ZRIBI.c_pi * (x[0] - x[2])
        np.testing.assert_allclose(model.C @ z, [x[0], surface], rtol=1e-12, atol=1e-9)


def _chain_response(plant: Any, omega: float) -> np.ndarray:
    """Frequency response from (u, d) to (top speed, surface torque, probe x1..x7) of the
    linear chain, built column by column from the plant's own derivative
    (drill_env.chain.chain_derivative without friction) in its interleaved coordinates."""
    chain = chain_from_parameters(plant)
    n = chain.n_nodes
    size = 2 * n - 1
    p = chain_parameter_vector(chain)
    a = np.zeros((size, size))
    dx = np.zeros(size)
    for c in range(size):
        e = np.zeros(size)
        e[c] = 1.0
        chain_derivative(e, 0.0, p, 0.0, 0.0, 1, dx)
        a[:, c] = dx
    b = np.zeros((size, 2))
    chain_derivative(np.zeros(size), 1.0, p, 0.0, 0.0, 1, dx)
    b[:, 0] = dx
    b[size - 1, 1] = -1.0 / chain.node_inertia_kg_m2[-1]  # d: a torque against the bit
    probes = probe_nodes(plant)
    rows = np.zeros((9, size))
    rows[0, 0] = 1.0
    rows[1, 1] = chain.element_stiffness_nm_rad[0]
    rows[1, 0] = chain.element_damping_nm_s_rad[0]
    rows[1, 2] = -chain.element_damping_nm_s_rad[0]
    for k in range(4):
        rows[2 + 2 * k, 2 * probes[k]] = 1.0
        if k < 3:
            rows[3 + 2 * k, 2 * probes[k] + 1 : 2 * probes[k + 1] : 2] = 1.0
    return rows @ np.linalg.solve(1j * omega * np.eye(size) - a, b)


@pytest.mark.parametrize("omega", [0.3, 2.0, 10.0])
def test_distributed_model_with_every_mode_is_the_chain(omega: float) -> None:
    """With every mode kept, the observer's model of a distributed string has the frequency
    response of the plant's chain from the drive torque and the bit torque to the measured
    signals and to the probe state."""
    plant = with_measured_depth(resolve_plant("field_2500m"), 700.0)
    n = chain_from_parameters(plant).n_nodes
    model = observer_model(plant, n)
    nz = model.A.shape[0]
    inputs = np.zeros((nz, 2))
    inputs[:, 0] = model.B
    inputs[:, 1] = model.A[:, -1]  # d, the last state, as an input: A's last column
    a = model.A[:-1, :-1]
    outs = np.vstack([model.C, model.outputs[:7]])[:, :-1]
    response = outs @ np.linalg.solve(1j * omega * np.eye(nz - 1) - a, inputs[:-1])
    reference = _chain_response(plant, omega)
    np.testing.assert_allclose(response, reference, rtol=1e-7, atol=1e-9 * abs(reference).max())


# -------------------------------------------------------------------------- the delay
def _replay(design: Any, measurements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The compiled observer over ``measurements``: its estimates (n, 8) and final state."""
    lp = pack_observer(design)
    ls = initial_observer_state(design)
    out = np.zeros((measurements.shape[0], 8))
    for k in range(measurements.shape[0]):
        observer_update(lp, 0, ls, 0, measurements[k], DT)
        out[k] = ls[OS_ESTIMATE : OS_ESTIMATE + 8]
    return out, ls


def _telemetry_stream(n: int, period: int, delay: int, seed: int) -> np.ndarray:
    """Measurement vectors of n steps: random surface signals and torques, and the telemetry
    as the channel delivers it (the last sample taken ``delay`` or more steps ago)."""
    rng = np.random.default_rng(seed)
    m = np.full((n, N_MEASUREMENT), np.nan)
    m[:, M_TOP_DRIVE_SPEED] = 10.0 + rng.standard_normal(n)
    m[:, M_SURFACE_TORQUE] = 8_000.0 + 500.0 * rng.standard_normal(n)
    m[:, M_APPLIED_TORQUE] = 12_000.0 + 1_000.0 * rng.standard_normal(n)
    values = 10.0 + rng.standard_normal(n)  # the bit speed sampled at each step
    for k in range(n):
        if k >= delay:
            sample = ((k - delay) // period) * period
            m[k, M_TELEMETRY_AGE] = (k - sample) * DT
            m[k, M_TELEMETRY_BIT_SPEED] = values[sample]
    return m


def _rerun(design: Any, m: np.ndarray, k: int) -> np.ndarray:
    """The estimate at step k of the fixed-gain filter run again from the start with every
    telemetry value delivered by step k used at the instant it was sampled (no delay)."""
    z = np.zeros(design.nz)
    h = design.outputs[X_BIT_SPEED]
    delivered = {}
    for j in range(k + 1):
        if not math.isnan(m[j, M_TELEMETRY_AGE]):
            sample = j - round(m[j, M_TELEMETRY_AGE] / DT)
            delivered[sample] = m[j, M_TELEMETRY_BIT_SPEED]
    for j in range(k + 1):
        y = m[j, [M_TOP_DRIVE_SPEED, M_SURFACE_TORQUE]]
        z = design.F @ z + design.g * m[j, M_APPLIED_TORQUE] + design.K @ y
        if j in delivered:
            z = z + design.telemetry_gain * (delivered[j] - h @ z)
    return design.outputs @ z


@pytest.mark.parametrize(
    ("period", "delay"),
    [(30, 75), (30, 60), (40, 10), (25, 0)],
    ids=["two in flight", "delay = 2 periods", "delay < period", "no delay"],
)
def test_delayed_telemetry_equals_the_filter_rerun_from_its_sample(period: int, delay: int) -> None:
    """The compiled observer folds a telemetry value in when it arrives; its estimate is then
    the one of the same filter re-run from the start with the value used at its sample
    instant (the snapshot, the correction through F^D and of the snapshots in flight)."""
    ch = channel(
        speed_noise_std_rad_s=0.5, torque_noise_std_nm=2_000.0, telemetry_period_s=period * DT,
        telemetry_delay_s=delay * DT, telemetry_noise_std_rad_s=0.05,
    )  # fmt: skip
    design = design_observer(ZRIBI, ch, ObserverGains())
    assert abs(design.v_delay).max() > 1e-3  # the telemetry matters over this delay
    n = 400
    m = _telemetry_stream(n, period, delay, seed=period + delay)
    out, ls = _replay(design, m)
    assert ls[OS_SKIPPED] == 0.0
    for k in (delay + 5, delay + period, 2 * delay + period + 3, n - 1):
        np.testing.assert_allclose(out[k], _rerun(design, m, k), rtol=1e-9, atol=1e-9)
    no_telemetry = m.copy()
    no_telemetry[:, [M_TELEMETRY_AGE, M_TELEMETRY_BIT_SPEED]] = np.nan
    assert abs(_replay(design, no_telemetry)[0][-1, 6] - out[-1, 6]) > 1e-3


def test_a_telemetry_value_the_design_does_not_expect_is_counted_not_used() -> None:
    """Values delivered with another delay than the design's are skipped (and counted)."""
    ch = channel(telemetry_period_s=0.03, telemetry_delay_s=0.06, telemetry_noise_std_rad_s=0.1)
    design = design_observer(ZRIBI, ch, ObserverGains())
    m = _telemetry_stream(300, 30, 45, seed=3)  # delivered after 45 steps, designed for 60
    out, ls = _replay(design, m)
    assert ls[OS_SKIPPED] == len({k - round(a / DT) for k, a in enumerate(m[:, M_TELEMETRY_AGE])
                                  if not math.isnan(a)})  # fmt: skip
    m[:, [M_TELEMETRY_AGE, M_TELEMETRY_BIT_SPEED]] = np.nan
    np.testing.assert_array_equal(out, _replay(design, m)[0])


# ------------------------------------------------------------------------------ in the env
def _estimate_errors(env_id: str, seed: int = 0, **kwargs: Any) -> np.ndarray:
    """Per decision after 20 s: the estimate errors x1..x7 from info, checked against the
    records' true state at the law's last plant step."""
    env = gym.make(env_id, base_controller="proposed", max_episode_steps=-1, **kwargs)
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    env.reset(seed=seed)
    errors = []
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
        assert not terminated
        done = truncated
        truth = records[0, -1, REC_X0 : REC_X0 + 7]
        row = [info[f"estimate_error_{name}"] for name in STATE_NAMES]
        estimate = [info[f"estimated_{name}"] for name in STATE_NAMES]
        np.testing.assert_allclose(np.subtract(estimate, row), truth, atol=1e-9)
        if info["time_s"] > 20.0:
            errors.append(row)
    return np.array(errors)


def test_estimate_converges_on_the_noise_free_four_dof_plant() -> None:
    """DrillString-v0 in surface mode, nominal plant, no noise: after 20 s the bit-speed
    estimate is within 0.1 rad/s (0.072 measured) and the top-drive and pipe speeds within
    0.01 rad/s (0.001 measured)."""
    e = _estimate_errors("DrillString-v0", randomize=False, observation="surface", **QUIET)
    assert abs(e[:, 6]).max() < 0.1
    assert abs(e[:, [0, 2]]).max() < 0.01


def test_estimate_converges_on_the_noise_free_field_string() -> None:
    """DrillStringField-v0 (its surface sensors at 100 Hz, telemetry, actuator), nominal
    string, no noise: the 8-mode model of a 103-node string; after 20 s the bit-speed error is
    within 0.25 rad/s (0.12 measured) with an rms below 0.05 rad/s (0.023 measured)."""
    e = _estimate_errors("DrillStringField-v0", randomize=False, **QUIET)
    assert abs(e[:, 6]).max() < 0.25
    assert np.sqrt(np.mean(e[:, 6] ** 2)) < 0.05


def test_estimate_tracks_with_the_field_defaults() -> None:
    """DrillStringField-v0 with every default (speed noise 0.05 rad/s, torque noise 250 N m,
    telemetry every 5 s, 5 s late, actuator dead time, lag and rate limit): after 20 s the
    bit-speed error stays within 1 rad/s with an rms below 0.25 rad/s (0.35 and 0.10
    measured)."""
    e = _estimate_errors("DrillStringField-v0", seed=1, randomize=False)
    assert abs(e[:, 6]).max() < 1.0
    assert np.sqrt(np.mean(e[:, 6] ** 2)) < 0.25


def test_delayed_telemetry_corrects_a_wrong_model() -> None:
    """On the 4-DOF plant of uncertainty condition 2 (c_pi, k_pi, c_dt 40-60 % above the
    controller's model) the surface-only estimate errs by 0.52 rad/s rms after 20 s; bit-speed
    telemetry every 0.1 s, 0.3 s late (noise 0.1 rad/s), folded in at its sample instants,
    brings it below half of that (0.13 measured)."""
    kwargs = {"randomize": False, "observation": "surface", "uncertainty": "condition2"}
    alone = _estimate_errors("DrillString-v0", **kwargs)[:, 6]
    helped = _estimate_errors(
        "DrillString-v0", telemetry_period_s=0.1, telemetry_delay_s=0.3,
        telemetry_noise_std_rad_s=0.1, **kwargs,
    )[:, 6]  # fmt: skip
    assert np.sqrt(np.mean(helped**2)) < 0.5 * np.sqrt(np.mean(alone**2))


@pytest.mark.parametrize(
    ("env_id", "seed"),
    [("DrillString-v0", 1), ("DrillString-v0", 3), ("DrillStringField-v0", 1),
     ("DrillStringField-v0", 2)],
)  # fmt: skip
def test_surface_smc_keeps_drilling_close_to_the_full_state_smc(env_id: str, seed: int) -> None:
    """A randomized drilling scenario with the proposed SMC on its observer (surface mode):
    no divergence, and IAE and RMSE within 1.25 times those of the same SMC measuring the
    whole state (0.56-1.04 times measured: benchmarks/observer_accuracy.py)."""
    metrics = {}
    for observation in ("state", "surface"):
        env = gym.make(
            env_id, base_controller="proposed", observation=observation, max_episode_steps=-1
        )
        metrics[observation] = episode_metrics(rollout(env, ZeroAction(), seed=seed))
    assert not metrics["surface"]["diverged"]
    for key in ("iae", "rmse"):
        assert metrics["surface"][key] <= 1.25 * metrics["state"][key], key


# -------------------------------------------------------------- only what is measured
def _surface_history(records: np.ndarray, hold: int) -> np.ndarray:
    """The measurement vectors a noise-free surface channel delivered over ``records`` (no
    telemetry): the held top-drive speed and surface torque, the torque of the last step."""
    n = records.shape[0]
    held = (np.arange(n) // hold) * hold
    m = np.full((n, N_MEASUREMENT), np.nan)
    m[:, M_TOP_DRIVE_SPEED] = records[held, REC_X0]
    m[:, M_SURFACE_TORQUE] = records[held, REC_SURFACE_TORQUE]
    m[0, M_APPLIED_TORQUE] = 0.0
    m[1:, M_APPLIED_TORQUE] = records[:-1, REC_TORQUE]
    return m


def _run_records(env_id: str, steps: int, **kwargs: Any) -> tuple[np.ndarray, CompiledLaw]:
    env = gym.make(env_id, base_controller="proposed", randomize=False, **QUIET, **kwargs)
    batch = env.unwrapped.batch  # type: ignore[attr-defined]
    env.reset(seed=0)
    law = compile_law(
        batch.controllers[0],
        batch.episodes[0].scenario.controller_model,
        env.unwrapped.config.torque_limits,  # type: ignore[attr-defined]
        env.unwrapped.config.measurement_channel(0.0),  # type: ignore[attr-defined]
    )
    np.testing.assert_array_equal(law.params, batch.arrays.law_params[0])
    chunks = []
    for _ in range(steps):
        env.step(np.zeros(1, dtype=np.float32))
        chunks.append(batch.records[0].copy())
    return np.concatenate(chunks), law


@pytest.mark.parametrize(
    ("env_id", "plants", "hold"),
    [
        ("DrillString-v0", [{}, {"parameters": dataclasses.replace(ZRIBI, mu_a=1.0, mu_0=0.7)}],
         1),
        ("DrillStringField-v0",
         [{}, {"parameters": dataclasses.replace(resolve_plant("field_2500m"), mu_a=0.95,
                                                 mu_0=0.65),
               "controller_parameters": "field_2500m"}],
         10),
    ],
    ids=["4-DOF, bit friction", "field string, bit friction"],
)  # fmt: skip
def test_the_torque_follows_from_the_surface_history_alone(
    env_id: str, plants: list[dict[str, Any]], hold: int
) -> None:
    """Two plants that differ downhole (the bit's friction) and run the same law: replayed
    from Python, the surface history of either one gives the torques that plant's law
    computed in the env, through either plant's law. Without telemetry the controller uses
    nothing but the surface signals and the torque it applied."""
    runs = [_run_records(env_id, 200, telemetry_period_s=None, observation="surface", **p)
            for p in plants]  # fmt: skip
    (records_a, law_a), (records_b, law_b) = runs
    np.testing.assert_array_equal(law_a.params, law_b.params)  # the same law
    bit_a, bit_b = records_a[:, REC_X0 + X_BIT_SPEED], records_b[:, REC_X0 + X_BIT_SPEED]
    assert abs(bit_a - bit_b).max() > 1.0  # different downhole
    for records in (records_a, records_b):
        history = _surface_history(records, hold)
        for law in (law_a, law_b):
            state = law.initial_state.copy()
            torques = [
                law.torque(state, history[k], records[k, REC_REFERENCE], DT)
                for k in range(len(history))
            ]
            np.testing.assert_array_equal(torques, records[:, REC_BASE_TORQUE])


# ---------------------------------------------------------------------- the law's parts
def test_with_the_state_measured_the_law_has_no_observer() -> None:
    """In state mode the law is the one of docs/specification.md section 3 (no observer
    block, no slots) and does not run an observer; a NaN state without an observer gives a
    NaN torque."""
    controller = make_controller("proposed")
    law = controller.compiled_law(None, None, channel=channel(observation="state"))  # type: ignore[call-arg]
    assert law.params.size == N_SMC_PARAMS == law.params[SMC_PARAMS_SIZE]
    assert law.info_slots == () and law.estimate_slots == ()
    m = np.full(N_MEASUREMENT, np.nan)
    m[M_TOP_DRIVE_SPEED] = m[M_SURFACE_TORQUE] = m[M_APPLIED_TORQUE] = 1.0
    assert math.isnan(law.torque(law.initial_state.copy(), m, 12.0, DT))


def test_surface_law_names_its_estimate_slots() -> None:
    controller = make_controller("csmc")
    law = controller.compiled_law(None, None, channel=channel())  # type: ignore[call-arg]
    assert law.estimate_slots == tuple((x, S_OBSERVER + OS_ESTIMATE + x) for x in range(7))
    assert law.info_slots == (("estimated_bit_torque_nm", S_OBSERVER + OS_ESTIMATE + 7),)
    m = np.full(N_MEASUREMENT, np.nan)
    m[M_TOP_DRIVE_SPEED], m[M_SURFACE_TORQUE], m[M_APPLIED_TORQUE] = 0.0, 0.0, 0.0
    state = law.initial_state.copy()
    assert law.torque(state, m, 12.0, DT) == pytest.approx(ZRIBI.J_dt * 12.0 + 3.0)


def test_python_path_runs_the_same_observer() -> None:
    """``controller.torque`` (from Python) and the compiled law give the same torques on a
    surface measurement stream (the controller's own default channel)."""
    controller = ProposedASMC()
    law = controller.compiled_law()
    state = law.initial_state.copy()
    m = _telemetry_stream(300, 5000, 5000, seed=4)
    for k in range(300):
        assert controller.torque(m[k], 12.0, DT) == law.torque(state, m[k], 12.0, DT)
    estimate = controller.estimate
    assert estimate is not None and np.all(np.isfinite(estimate))


def test_compile_law_passes_the_channel_only_to_laws_that_take_it() -> None:
    seen: list[Any] = []

    class TwoArguments:
        def compiled_law(self, model: Any = None, torque_limits: Any = None) -> Any:
            seen.append((model, torque_limits))
            return "law"

    class WithChannel:
        def compiled_law(
            self, model: Any = None, torque_limits: Any = None, channel: Any = None
        ) -> Any:
            seen.append(channel)
            return "law"

    ch = channel()
    assert compile_law(TwoArguments(), "m", None, ch) == "law"  # type: ignore[arg-type]
    assert compile_law(WithChannel(), "m", None, ch) == "law"  # type: ignore[arg-type]
    assert seen == [("m", None), ch]


def test_compiled_law_slots_are_checked() -> None:
    law = make_controller("csmc").compiled_law()  # type: ignore[attr-defined]
    size = law.initial_state.size
    with pytest.raises(ValueError, match=r"CompiledLaw.estimate_slots: state index 7 is out"):
        law._replace(estimate_slots=((7, 0),)).validated()
    with pytest.raises(ValueError, match=rf"CompiledLaw.info_slots: slot {size} is out of range"):
        law._replace(info_slots=(("x", size),)).validated()
    with pytest.raises(ValueError, match=r"info key must be a non-empty string"):
        law._replace(info_slots=(("", 0),)).validated()


def test_observer_gains_are_validated() -> None:
    with pytest.raises(ValueError, match=r"ObserverGains.modes = 1 is out of range: allowed an"):
        ObserverGains(modes=1)
    with pytest.raises(ValueError, match=r"ObserverGains.bit_torque_walk_nm = 0.0 is out of"):
        ObserverGains(bit_torque_walk_nm=0.0)
    with pytest.raises(TypeError, match=r"observer must be an ObserverGains, got dict"):
        ProposedASMC(observer={})  # type: ignore[arg-type]


def test_too_many_telemetry_values_in_flight_is_a_clear_error() -> None:
    ch = channel(telemetry_period_s=0.001, telemetry_delay_s=2.0)
    with pytest.raises(ValueError, match=r"= 2000 values in flight is out of range for the"):
        design_observer(ZRIBI, ch, ObserverGains())


def test_measurement_channel_is_validated() -> None:
    with pytest.raises(ValueError, match=r"observation = 'x' is not a known mode"):
        channel(observation="x")
    with pytest.raises(ValueError, match=r"telemetry_delay_s = -1.0 is out of range"):
        channel(telemetry_delay_s=-1.0)


def test_vector_env_reports_the_estimates_of_each_string_as_the_single_env() -> None:
    kwargs = {"base_controller": "proposed", "episode_s": 2.0}
    venv = gym.make_vec("DrillStringField-v0", num_envs=2, **kwargs)
    venv.reset(seed=10)
    singles = [gym.make("DrillStringField-v0", **kwargs) for _ in range(2)]
    for i, env in enumerate(singles):
        env.reset(seed=10 + i)
    for _ in range(5):
        _, _, _, _, infos = venv.step(np.zeros((2, 1), dtype=np.float32))
        for i, env in enumerate(singles):
            _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
            for key in ("estimated_bit_speed_rad_s", "estimate_error_bit_speed_rad_s",
                        "estimated_bit_torque_nm"):  # fmt: skip
                assert infos[key][i] == info[key]
