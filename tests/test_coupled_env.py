"""``DrillStringCoupled-v0`` (drill_env.coupled_env): the Gymnasium and SB3 contracts,
determinism, bad input, and the chain's equations against a scipy integration of the 4-DOF
string with the bit's axial motion, written here from docs/specification.md and
docs/coupled-model.md."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt
import pytest
from gymnasium.utils.env_checker import check_env

import drill_env
from drill_env.coupled import RGD_PRESETS
from drill_env.coupled_env import OBSERVATION_NAMES, DrillStringCoupledEnv
from drill_env.parameters import PRESETS


@pytest.mark.parametrize(
    "keywords",
    [{}, {"action_mode": "torque"}, {"action_mode": "force"}, {"torque_loop": "none"}],
    ids=["both", "torque", "force", "absolute_torque"],
)
def test_checkers_pass(keywords: dict[str, Any]) -> None:
    check_env(gym.make(drill_env.COUPLED_ENV_ID, **keywords).unwrapped)
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(gym.make(drill_env.COUPLED_ENV_ID, **keywords).unwrapped)


def test_registered_and_sized() -> None:
    env = gym.make(drill_env.COUPLED_ENV_ID, action_mode="torque")
    assert env.action_space.shape == (1,)
    assert env.observation_space.shape == (len(OBSERVATION_NAMES),)


def _rollout(seed: int, steps: int = 30) -> tuple[npt.NDArray[np.float64], list[float]]:
    env = DrillStringCoupledEnv()
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    observations, rewards = [obs], []
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        observations.append(obs)
        rewards.append(float(reward))
        assert not terminated
    return np.array(observations, dtype=np.float64), rewards


def test_same_seed_same_trajectory_bit_for_bit() -> None:
    a, ra = _rollout(3)
    b, rb = _rollout(3)
    c, _ = _rollout(4)
    assert np.array_equal(a, b) and ra == rb
    assert not np.array_equal(a, c)


def test_reward_is_the_sum_of_its_terms_and_info_has_units() -> None:
    env = DrillStringCoupledEnv(episode_s=0.5)
    env.reset(seed=0)
    steps = 0
    truncated = False
    while not truncated:
        _, reward, terminated, truncated, info = env.step(np.zeros(2, dtype=np.float32))
        steps += 1
        assert not terminated
        assert float(reward) == pytest.approx(sum(info["reward_terms"].values()), rel=1e-12)
    assert steps == 10
    for key in ("wob_n", "tob_nm", "rop_m_s", "mse_pa", "bounce_fraction", "top_drive_power_w"):
        assert math.isfinite(info[key]), key
    metrics = env.episode_metrics()
    assert metrics["rop_m_s"] == pytest.approx(info["depth_m"] / 0.5, rel=1e-9)
    assert metrics["mse_pa"] > 0


def test_low_speed_and_high_force_bounce() -> None:
    env = DrillStringCoupledEnv(randomize=False)
    env.reset(seed=0)
    bounced = 0.0
    for _ in range(200):
        _, _, terminated, _, info = env.step(np.zeros(2, dtype=np.float32))
        assert not terminated
        bounced += info["bounce_fraction"]
    assert bounced > 0
    assert env.episode_metrics()["bounce_fraction"] == pytest.approx(bounced / 200, rel=1e-9)


def test_first_decisions_match_scipy() -> None:
    """While the delayed angle is in the steady history, the plant is an ODE: the 4-DOF chain
    (top drive torque ``u``) with the bit cutting ``d_n = U - r (phi_bi - 2 pi / n)``."""
    integrate = pytest.importorskip("scipy.integrate")
    env = DrillStringCoupledEnv(randomize=False, torque_loop="none", force_loop="none")
    env.reset(seed=0)
    s, b = PRESETS["zribi2024"], RGD_PRESETS["rgd_a"]
    from drill_env.coupled import steady_state

    steady = steady_state(b, 12.0, 90e3)
    r, blade = steady.surface_slope_m_rad, 2 * math.pi / b.blades
    torque, force = 0.5 * 1.1 * 50_000.0, 0.5 * 0.8 * 250e3
    y0 = env._y.copy()  # (U, V, phi_bi, w_bi, phi_dt, phi_pi, phi_co, w_dt, w_pi, w_co)

    def rhs(t: float, y: npt.NDArray[np.float64]) -> list[float]:
        u, v, p_bi, w_bi, p_dt, p_pi, p_co, w_dt, w_pi, w_co = y
        dn = u - r * (p_bi - blade)
        t_pi = s.k_pi * (p_dt - p_pi) + s.c_pi * (w_dt - w_pi)
        t_co = s.k_co * (p_pi - p_co) + s.c_co * (w_pi - w_co)
        t_bi = s.k_bi * (p_co - p_bi) + s.c_bi * (w_co - w_bi)
        weight = b.k_a * dn + b.contact_force_n
        bit_torque = b.k_t * dn + b.contact_torque_nm
        return [
            v,
            (force - weight) / b.axial_mass_kg,
            w_bi,
            (t_bi - s.c_bit * w_bi - bit_torque) / s.J_bi,
            w_dt,
            w_pi,
            w_co,
            (torque - s.c_dt * w_dt - t_pi) / s.J_dt,
            (t_pi - t_co) / s.J_pi,
            (t_co - t_bi) / s.J_co,
        ]

    reference = integrate.solve_ivp(
        rhs, (0.0, 0.1), y0, method="DOP853", rtol=1e-12, atol=1e-14, t_eval=[0.05, 0.1]
    )
    for k in range(2):
        _, _, _, _, info = env.step(np.array([0.1, -0.2], dtype=np.float32))
        assert info["top_drive_torque_nm"] == pytest.approx(torque)
        assert info["applied_force_n"] == pytest.approx(force)
        assert not info["bit_stuck"] and env._y[2] < blade
        expected = reference.y[:, k]
        assert np.allclose(env._y, expected, rtol=1e-7, atol=1e-9), env._y - expected


@pytest.mark.parametrize(
    ("keywords", "error", "match"),
    [
        ({"bogus": 1}, TypeError, "unrecognized keyword"),
        ({"applied_force_n": 20e3}, ValueError, "applied_force_n = 20000.0 is out of range"),
        ({"action_mode": "drift"}, ValueError, "action_mode = 'drift' is not a known"),
        ({"action_mode": "force", "torque_loop": "none"}, ValueError, "needs a torque loop"),
        ({"control_dt_s": 0.00015}, ValueError, "control_dt_s = 0.00015"),
        ({"string": "nope"}, ValueError, "string = 'nope' is not a known preset"),
        ({"reward_weights": {"rop": -1.0}}, ValueError, "reward_weights.rop = -1.0"),
    ],
)
def test_bad_keywords(keywords: dict[str, Any], error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        DrillStringCoupledEnv(**keywords)


def test_bad_actions() -> None:
    env = DrillStringCoupledEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must have shape \(2,\), got shape \(3,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(np.array([np.nan, 0.0]))
    hostile = (
        np.array([0.1j, 0.0]),
        np.array(["0.5", "0"]),
        np.array([True, False]),
        np.ma.masked_array([0.0, 0.0], mask=[True, False]),
        [10**400, 0],
    )
    for action in hostile:
        with pytest.raises(ValueError, match="action must be"):
            env.step(action)
    env.step(np.zeros(2))  # the episode goes on
    with pytest.raises(ValueError, match="options"):
        env.reset(seed=0, options={"x": 1})


# --------------------------------------------------------------------------- vector env
def test_vector_env_reproduces_single_envs_bit_for_bit() -> None:
    vec = gym.make_vec(drill_env.COUPLED_ENV_ID, num_envs=3, episode_s=0.3)
    assert type(vec.unwrapped).__name__ == "DrillStringCoupledVectorEnv"
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (9, 3, 2)).astype(np.float32)
    obs, _ = vec.reset(seed=10)
    trajectories = [[obs]]
    rewards, ends = [], []
    for a in actions:
        obs, reward, terminated, truncated, info = vec.step(a)
        trajectories.append([obs])
        rewards.append(reward)
        ends.append(terminated | truncated)
        assert set(info["reward_terms"]) >= {"rop", "bounce", "_rop"}
    for i in range(3):
        env = DrillStringCoupledEnv(episode_s=0.3)
        single = [env.reset(seed=10 + i)[0]]
        single_rewards = []
        for k, a in enumerate(actions):
            if k > 0 and ends[k - 1][i]:  # next-step autoreset: this step resets
                single.append(env.reset()[0])
                single_rewards.append(0.0)
                continue
            o, r, _, _, _ = env.step(a[i])
            single.append(o)
            single_rewards.append(float(r))
        got = np.array([t[0][i] for t in trajectories])
        assert np.array_equal(got[:7], np.array(single)[:7])  # up to the first autoreset
        assert [float(r[i]) for r in rewards[:6]] == single_rewards[:6]
    assert ends[5].all()  # 0.3 s of 0.05 s decisions


def test_vector_env_bad_input() -> None:
    with pytest.raises(ValueError, match="num_envs = 0 is out of range"):
        gym.make_vec(drill_env.COUPLED_ENV_ID, num_envs=0)
    vec = gym.make_vec(drill_env.COUPLED_ENV_ID, num_envs=2)
    with pytest.raises(RuntimeError, match="reset"):
        vec.step(np.zeros((2, 2)))
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must have shape \(2, 2\), got shape \(3, 2\)"):
        vec.step(np.zeros((3, 2)))


# ---------------------------------------------------------------------------- rendering
def test_rgb_array_frames() -> None:
    env = gym.make(drill_env.COUPLED_ENV_ID, render_mode="rgb_array", episode_s=1.0)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, dtype=np.float32))
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
    env.close()


def test_bad_render_mode_and_headless_human(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ValueError, match="render_mode = 'video' is not valid"):
        DrillStringCoupledEnv(render_mode="video")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("MPLBACKEND", raising=False)
    if not __import__("sys").platform.startswith(("win", "darwin")):
        with pytest.raises(RuntimeError, match="needs a display"):
            DrillStringCoupledEnv(render_mode="human")


# ---------------------------------------------------------------------- hook-speed input
def test_hook_speed_input_is_a_spring_to_the_moving_hook() -> None:
    """``F_ax = W_0 + K (x_hook - U)``: with the hook held still the force falls by ``K`` per
    metre drilled; at the steady rate of penetration it stays at the set point on average."""
    k = 7.26e5
    still = DrillStringCoupledEnv(
        randomize=False, axial_input="hook_speed", force_loop="none", action_mode="force"
    )
    still.reset(seed=0)
    for _ in range(10):
        _, _, _, _, info = still.step(np.zeros(1, dtype=np.float32))
        assert info["hook_speed_m_s"] == 0.0
        assert info["applied_force_n"] == pytest.approx(90e3 - k * info["depth_m"], rel=1e-12)
    steady = DrillStringCoupledEnv(
        randomize=False, axial_input="hook_speed", reference_speed_rad_s=20.0,
        applied_force_n=60e3, string="zribi2024",
    )  # fmt: skip
    steady.reset(seed=0)
    for _ in range(200):
        _, _, _, _, info = steady.step(np.zeros(2, dtype=np.float32))
    assert info["hook_speed_m_s"] == pytest.approx(0.02366, rel=2e-3)  # V0 at 60 kN, 20 rad/s
    assert info["applied_force_n"] == pytest.approx(60e3, rel=0.05)


def test_stuck_bit_lifted_stays_wedged_until_it_turns() -> None:
    """The stated rule: a bit stuck on the rock does not move axially (S1); a hook pull beyond
    the string's weight is held by the rock as a negative weight on bit until the bit turns
    again, and then it lifts (regime UP, then off the rock)."""
    env = DrillStringCoupledEnv(
        randomize=False, axial_input="hook_speed", force_loop="none", torque_loop="none"
    )
    env.reset(seed=0)
    no_torque, hold, lift = -1.0, 0.0, -1.0  # top drive at zero torque; hook still, then up
    for _ in range(400):  # the string unwinds and the bit sticks
        _, _, terminated, _, info = env.step(np.array([no_torque, hold], dtype=np.float32))
        if info["bit_stuck"] and info["stuck_fraction"] == 1.0:
            break
    assert info["bit_stuck"]
    stuck_depth = info["depth_m"]
    wobs = []
    for _ in range(40):  # 2 s at 0.1 m/s: 0.2 m of lift, far more than the weight on bit
        _, _, terminated, _, info = env.step(np.array([no_torque, lift], dtype=np.float32))
        assert not terminated and info["bit_stuck"]
        assert info["depth_m"] == stuck_depth
        wobs.append(info["wob_n"])
    # The reaction is the whole applied force: its mean over the decision's plant steps.
    ramp = 7.26e5 * 0.1 * (0.05 - 1e-4) / 2
    assert wobs[-1] < -50e3 and wobs[-1] == pytest.approx(info["applied_force_n"] + ramp)
    # The top drive turns it free again: the bit then comes up off the rock.
    off = False
    for _ in range(400):
        _, _, _, _, info = env.step(np.array([0.0, lift], dtype=np.float32))
        off = off or info["off_bottom"]
    assert off and info["depth_m"] < stuck_depth


# ------------------------------------------------------------------ registered torque loops
def test_compiled_torque_loop_by_name_or_object_and_its_residual() -> None:
    baselines = pytest.importorskip("baselines")
    runs = []
    for loop in ("stiff_pi", baselines.StiffPI()):
        env = DrillStringCoupledEnv(randomize=False, torque_loop=loop, episode_s=2.0)
        env.reset(seed=0)
        obs = [env.step(np.array([0.2, 0.0], dtype=np.float32))[0] for _ in range(20)]
        runs.append(np.array(obs))
    assert np.array_equal(runs[0], runs[1])
    env = DrillStringCoupledEnv(randomize=False, torque_loop="stiff_pi", episode_s=5.0)
    env.reset(seed=0)
    for _ in range(100):
        _, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
    assert info["top_drive_speed_rad_s"] == pytest.approx(12.0, rel=1e-2)  # a stiff loop


def test_bad_loop_names() -> None:
    with pytest.raises(ValueError, match="torque_loop = 'fast' is not a known torque loop"):
        DrillStringCoupledEnv(torque_loop="fast")
    with pytest.raises(ValueError, match="force_loop = 'driller' is not a known axial loop"):
        DrillStringCoupledEnv(force_loop="driller")
    with pytest.raises(ValueError, match="axial_input = 'rope' is not a known"):
        DrillStringCoupledEnv(axial_input="rope")
    with pytest.raises(ValueError, match="hook_stiffness_n_m = -1.0 is out of range"):
        DrillStringCoupledEnv(hook_stiffness_n_m=-1.0)
    with pytest.raises(TypeError, match="torque_loop must be"):
        DrillStringCoupledEnv(torque_loop=3)


def test_depth_of_cut_in_info_is_steady_drilling_at_the_start() -> None:
    """At reset the bit sits on the steady-drilling surface: ``d_n = d_0`` of section 6."""
    from drill_env.coupled import steady_state

    env = DrillStringCoupledEnv(randomize=False)
    _, info = env.reset(seed=0)
    d0 = steady_state(RGD_PRESETS["rgd_a"], 12.0, 90e3).depth_of_cut_m
    assert info["depth_of_cut_m"] == pytest.approx(d0, rel=1e-9)
