"""The controller hook (:mod:`drill_env.control`): the compiled-law signature, calling a law by
its address, and the registry of controllers by name."""

from __future__ import annotations

from importlib import metadata
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from numba import carray, cfunc, njit

import drill_env  # noqa: F401  (registers DrillString-v0)
import drill_env.options
from baselines import BUILT_IN, COMPILED_LAWS
from drill_env import control
from drill_env.control import (
    ENTRY_POINT_GROUP,
    LAW_SIGNATURE,
    CompiledLaw,
    controller_names,
    make_controller,
    register_controller,
)
from drill_env.evaluation import ZeroAction, rollout
from drill_env.layout import M_STATE, N_MEASUREMENT


# A user's compiled law: a proportional loop on the top-drive speed, written in a test.
@cfunc(LAW_SIGNATURE, cache=True)
def _p_law(lp_ptr, ls_ptr, m_ptr, ref, dt):  # type: ignore[no-untyped-def]
    lp = carray(lp_ptr, (2,))
    ls = carray(ls_ptr, (1,))
    m = carray(m_ptr, (N_MEASUREMENT,))
    ls[0] = ref - m[M_STATE]
    return lp[0] + lp[1] * ls[0]


@njit(cache=True)
def _not_a_cfunc(x):  # type: ignore[no-untyped-def]
    return x


class _PLoop:
    """A compiled controller defined outside the project: torque = u0 + kp (ref - x1)."""

    def __init__(self, u0: float = 13_000.0, kp: float = 2_000.0) -> None:
        self.params = np.array([u0, kp])

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
        return float(self.params[0] + self.params[1] * (reference_speed_rad_s - measurement[0]))

    def compiled_law(self, model: Any = None, torque_limits: Any = None) -> CompiledLaw:
        return CompiledLaw(_p_law, self.params, np.zeros(1), error_slot=0)


def test_a_users_compiled_law_runs_in_the_loop_like_its_python_twin() -> None:
    """The kernel calls any cfunc of the law signature by its address: a controller defined
    here runs in the compiled loop and gives the torques its Python ``torque`` gives."""
    env = gym.make(
        "DrillString-v0", randomize=False, base_controller=_PLoop(), episode_s=2.0,
        noise_std_rad_s=0.0, control_dt_s=0.1,
    )  # fmt: skip
    trace = rollout(env, ZeroAction(), seed=0)
    expected = 13_000.0 + 2_000.0 * (trace.reference_rad_s - trace.top_drive_speed_rad_s)
    np.testing.assert_allclose(trace.base_torque_nm, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        trace.sliding_variable, trace.reference_rad_s - trace.top_drive_speed_rad_s, atol=1e-12
    )
    assert not np.any(trace.adaptive_gain)


def test_compiled_law_checks_its_parts() -> None:
    law = CompiledLaw(_p_law, np.array([1.0, 2.0]), np.zeros(1), error_slot=0).validated()
    assert law.address == _p_law.address and law.params.dtype == np.float64
    with pytest.raises(TypeError, match="must be a numba cfunc with signature"):
        CompiledLaw(_not_a_cfunc, np.ones(2), np.zeros(1)).validated()
    with pytest.raises(TypeError, match="must be a numba cfunc with signature"):
        CompiledLaw(lambda *a: 0.0, np.ones(2), np.zeros(1)).validated()
    with pytest.raises(ValueError, match=r"CompiledLaw\.gain_slot = 3 is out of range"):
        CompiledLaw(_p_law, np.ones(2), np.zeros(1), gain_slot=3).validated()
    with pytest.raises(ValueError, match=r"CompiledLaw\.params must be a non-empty 1-D"):
        CompiledLaw(_p_law, np.ones((2, 2)), np.zeros(1)).validated()


def test_calling_a_law_through_its_address_from_python() -> None:
    law = CompiledLaw(_p_law, np.array([100.0, 10.0]), np.zeros(1), error_slot=0)
    state = np.zeros(1)
    measurement = np.zeros(N_MEASUREMENT)
    measurement[M_STATE] = 4.0
    assert law.torque(state, measurement, 6.0, 1e-3) == 120.0
    assert state[0] == 2.0
    with pytest.raises(TypeError, match="C-contiguous float64"):
        law.torque(np.zeros(1, dtype=np.float32), measurement, 6.0, 1e-3)


# ------------------------------------------------------------------------------ registry
def test_every_built_in_controller_is_registered_and_offered_as_an_entry_point() -> None:
    names = controller_names()
    assert list(BUILT_IN) == names[: len(BUILT_IN)]
    offered = {e.name: e.value for e in metadata.entry_points(group=ENTRY_POINT_GROUP)}
    for name, cls in BUILT_IN.items():
        assert offered[name] == f"{cls.__module__}:{cls.__name__}"


@pytest.mark.parametrize("name", list(BUILT_IN))
def test_every_registered_law_is_dispatched(name: str) -> None:
    """Each built-in controller hands the loop its own compiled law, and the loop's base torque
    equals what the same law computes from Python on the loop's own measurements."""
    controller = make_controller(name)
    law = controller.compiled_law()  # type: ignore[attr-defined]
    assert law.function is COMPILED_LAWS[name]
    env = gym.make(
        "DrillString-v0", randomize=False, base_controller=name, episode_s=1.0,
        noise_std_rad_s=0.0, control_dt_s=0.1,
    )  # fmt: skip
    trace = rollout(env, ZeroAction(), seed=0)
    controller.reset()
    python = [
        controller.torque(x, ref, 1e-3)
        for x, ref in zip(trace.states, trace.reference_rad_s, strict=True)
    ]
    np.testing.assert_array_equal(trace.base_torque_nm, python)


def test_registry_refuses_a_taken_name_and_lists_the_valid_ones() -> None:
    register_controller("csmc", BUILT_IN["csmc"])  # the same factory again: harmless
    with pytest.raises(ValueError, match="controller name 'csmc' is already registered"):
        register_controller("csmc", _PLoop)
    with pytest.raises(ValueError, match=r"unknown controller 'pid': valid names are csmc, "):
        make_controller("pid")
    with pytest.raises(TypeError, match="must be callable"):
        register_controller("thing", 3)  # type: ignore[arg-type]


def test_a_registered_controller_is_found_by_name_in_the_env(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(control, "_FACTORIES", dict(control._FACTORIES))  # undone afterwards
    register_controller("test_p_loop", _PLoop)
    assert "test_p_loop" in controller_names()
    env = gym.make("DrillString-v0", base_controller="test_p_loop", randomize=False)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    assert info["base_torque_nm"] > 0


# ------------------------------------------------------------------- the named measurement
def test_measurement_reads_its_signals_by_name_and_by_index() -> None:
    from drill_env.layout import M_SURFACE_TORQUE, MEASUREMENT_NAMES

    values = np.arange(N_MEASUREMENT, dtype=float)
    m = control.Measurement(values)
    assert len(MEASUREMENT_NAMES) == N_MEASUREMENT
    for k, name in enumerate(MEASUREMENT_NAMES):
        assert getattr(m, name) == m[k] == values[k] == m.signal(name)
    assert m.surface_torque_nm == values[M_SURFACE_TORQUE]
    assert np.array_equal(m[:7], values[:7]) and float(np.sum(m)) == values.sum()
    with pytest.raises(AttributeError, match="no attribute 'bit_speed'; its signals are "):
        _ = m.bit_speed
    with pytest.raises(KeyError, match="'x7' is not a signal of the measurement"):
        m.signal("x7")
    with pytest.raises(ValueError, match=r"a measurement has shape \(12,\), got \(7,\)"):
        control.Measurement(np.zeros(7))


def test_a_missing_signal_names_the_keyword_that_provides_it() -> None:
    channel = drill_env.options.FieldEnvConfig().measurement_channel()
    missing = control.Measurement.missing_signals(channel)
    assert "bit_speed_rad_s" in missing and "surface_torque_nm" not in missing
    assert "telemetry_bit_speed_rad_s" not in missing  # the field env's telemetry
    m = control.Measurement(np.full(N_MEASUREMENT, np.nan), missing)
    assert np.isnan(m[6])  # by index: NaN, as before
    with pytest.raises(control.MissingSignalError, match="observation='state'"):
        _ = m.bit_speed_rad_s
    paper = control.Measurement.missing_signals(drill_env.options.EnvConfig().measurement_channel())
    assert paper == {"telemetry_bit_speed_rad_s", "telemetry_age_s"}
    with pytest.raises(control.MissingSignalError, match="telemetry_period_s"):
        _ = control.Measurement(np.zeros(N_MEASUREMENT), paper).telemetry_age_s


class _BitSpeedLoop:
    """A Python controller that reads the bit speed by name."""

    def __init__(self) -> None:
        self.seen: list[type] = []

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
        self.seen.append(type(measurement))
        return 13_000.0 + 2_000.0 * (reference_speed_rad_s - measurement.bit_speed_rad_s)


def test_python_controllers_get_the_named_measurement_in_both_envs() -> None:
    loop = _BitSpeedLoop()
    env = gym.make("DrillString-v0", randomize=False, base_controller=loop, episode_s=0.1)
    rollout(env, ZeroAction(), seed=0)
    assert loop.seen and set(loop.seen) == {control.Measurement}
    field = gym.make("DrillStringField-v0", randomize=False, base_controller=_BitSpeedLoop())
    field.reset(seed=0)
    with pytest.raises(control.MissingSignalError, match="measurement.bit_speed_rad_s .*'state'"):
        field.step(np.zeros(1, dtype=np.float32))
    state = gym.make(
        "DrillStringField-v0", randomize=False, base_controller=_BitSpeedLoop(),
        observation="state", episode_s=0.05, control_dt_s=0.05,
    )  # fmt: skip
    rollout(state, ZeroAction(), seed=0)


def test_controller_policy_hands_a_named_measurement_of_what_the_observation_carries() -> None:
    from baselines import ControllerPolicy

    class Reads:
        def __init__(self, name: str) -> None:
            self.name = name

        def reset(self) -> None:
            pass

        def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
            return 13_000.0 + 0.0 * getattr(measurement, self.name)

    env = gym.make("DrillString-v0", randomize=False, episode_s=0.1)
    obs, _ = env.reset(seed=0)
    for name in ("bit_speed_rad_s", "surface_top_drive_speed_rad_s"):
        action, _ = ControllerPolicy.for_env(Reads(name), env).predict(obs)
        assert action.shape == (1,)
    policy = ControllerPolicy.for_env(Reads("surface_torque_nm"), env)
    with pytest.raises(control.MissingSignalError, match="surface_torque_nm is not available"):
        policy.predict(obs)
