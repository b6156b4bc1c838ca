"""A batch of drill strings stepped together: the engine under the single and vector envs.

:class:`StringBatch` owns the per-string arrays that the compiled kernel advances, the
per-string scenarios and random generators, and turns kernel output into observations,
reward terms and info. The single env is a batch of one, so the vector env reproduces it bit
for bit.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env import kernel
from drill_env.config import EnvConfig
from drill_env.control import CompiledController, CompiledLaw, Controller
from drill_env.control_laws import LAW_NONE, N_LAW_PARAMS, N_LAW_STATE
from drill_env.friction import STUCK
from drill_env.observation import (
    N_STATE_OBS,
    OBS_BOUND,
    SPEED_SCALE_RAD_S,
    observation_size,
    state_scales,
)
from drill_env.parameters import (
    N_PLANT_PARAMS,
    PLANT_DT_S,
    plant_parameter_vector,
    resolve_parameters,
)
from drill_env.scenarios import (
    MAX_KNOTS,
    EpisodeScenario,
    SpeedProfile,
    WobProfile,
    knot_arrays,
    resolve_uncertainty,
    spawn_generators,
)

__all__ = ["PER_EPISODE_KEYWORDS", "StringBatch", "resolve_controller"]

PER_EPISODE_KEYWORDS: Final = (
    "parameters",
    "randomize",
    "wob_n",
    "wob_step_time_s",
    "wob_final_n",
    "reference_speed_rad_s",
    "uncertainty",
    "uncertainty_reading",
    "noise_std_rad_s",
    "episode_s",
    "randomization",
)
"""Keywords that ``reset(options=...)`` may change for one episode; the others shape the
spaces or the compiled loop and are fixed at ``make``."""

PARALLEL_THRESHOLD: Final = 64
"""Batches at least this large use numba's threads."""


def resolve_controller(value: str | Controller | None) -> Controller | None:
    """A controller object from a registered name (see :mod:`baselines`) or the object itself."""
    if value is None or not isinstance(value, str):
        return value
    from baselines import make_controller  # the registry lives with the controllers

    return make_controller(value)


def episode_config(base: EnvConfig, options: dict[str, Any] | None) -> EnvConfig:
    """``base`` with the per-episode ``options`` applied and validated."""
    if not options:
        return base
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict, got {type(options).__name__}")
    fixed = sorted(set(options) & (set(EnvConfig.keywords()) - set(PER_EPISODE_KEYWORDS)))
    if fixed:
        raise ValueError(
            f"option(s) {', '.join(fixed)} cannot change per episode: set them at make; "
            f"per-episode options: {', '.join(PER_EPISODE_KEYWORDS)}"
        )
    unknown = sorted(set(options) - set(EnvConfig.keywords()))
    if unknown:
        raise ValueError(
            f"unknown option(s): {', '.join(unknown)}; valid options: "
            f"{', '.join(PER_EPISODE_KEYWORDS)}"
        )
    return EnvConfig.from_kwargs(options, base)


def scenario_for(config: EnvConfig, generators: dict[str, np.random.Generator]) -> EpisodeScenario:
    """The episode's scenario: drawn when ``config.randomize``, exact otherwise."""
    nominal = resolve_parameters(config.parameters)
    reading = "plant" if config.uncertainty_reading == "plant" else "controller"
    if config.randomize:
        return EpisodeScenario.draw(
            config.randomization,
            generators,
            config.episode_s,
            nominal,
            reading,
            config.noise_std_rad_s,
        )
    ref = config.reference_speed_rad_s
    return EpisodeScenario(
        wob=WobProfile(config.wob_n, config.wob_step_time_s, config.wob_final_n),
        reference=ref if isinstance(ref, SpeedProfile) else SpeedProfile.constant(ref),
        deltas=resolve_uncertainty(config.uncertainty),
        reading=reading,
        nominal=nominal,
        noise_std_rad_s=config.noise_std_rad_s,
    )


@dataclass
class _StringEpisode:
    config: EnvConfig
    scenario: EpisodeScenario
    seed_root: np.random.SeedSequence
    noise_rng: np.random.Generator
    actions_clipped: int = 0


class StringBatch:
    """``num`` drill strings sharing one :class:`EnvConfig` and one control law."""

    def __init__(self, config: EnvConfig, num: int) -> None:
        self.config = config
        self.num = num
        self.substeps = config.substeps
        self.residual = config.residual
        self.obs_size = observation_size(self.residual)
        controller = resolve_controller(config.base_controller)
        self.compiled = isinstance(controller, CompiledController)
        self.controllers: list[Controller] = []
        if controller is not None:
            self.controllers = [controller] + [copy.deepcopy(controller) for _ in range(num - 1)]
        n, s = num, self.substeps
        self.x = np.zeros((n, 7))
        self.mode = np.zeros(n, dtype=np.int64)
        self.step_index = np.zeros(n, dtype=np.int64)
        self.status = np.zeros(n, dtype=np.int64)
        self.plant = np.zeros((n, N_PLANT_PARAMS))
        self.wob_t = np.zeros((n, MAX_KNOTS))
        self.wob_v = np.zeros((n, MAX_KNOTS))
        self.wob_n = np.ones(n, dtype=np.int64)
        self.ref_t = np.zeros((n, MAX_KNOTS))
        self.ref_v = np.zeros((n, MAX_KNOTS))
        self.ref_n = np.ones(n, dtype=np.int64)
        self.noise = np.zeros((n, s + 1, 4))
        self.noise_std = np.zeros(n)
        self.law_id = LAW_NONE
        self.law_params = np.zeros((n, N_LAW_PARAMS))
        self.law_state = np.zeros((n, N_LAW_STATE))
        self.command = np.zeros(n)
        self.records = np.zeros((n, s, kernel.N_RECORD))
        self.meas = np.zeros((n, 7))
        self.last_u = np.zeros(n)
        self.summary = np.zeros((n, kernel.N_SUMMARY))
        self.episodes: list[_StringEpisode | None] = [None] * n
        self._obs_scale = np.empty(self.obs_size)
        self._obs_scale[:7] = 1.0 / state_scales()
        self._obs_scale[7] = 1.0 / SPEED_SCALE_RAD_S
        self._obs_scale[8:] = 1.0 / config.torque_scale_nm
        if self.residual:
            self._obs_scale[N_STATE_OBS + 1] = 1.0 / SPEED_SCALE_RAD_S
        self._advance = (
            kernel.advance_batch_parallel if n >= PARALLEL_THRESHOLD else kernel.advance_batch
        )

    # ------------------------------------------------------------------ reset
    def reset_string(
        self,
        i: int,
        seed: int | None,
        options: dict[str, Any] | None,
        previous_root: np.random.SeedSequence | None = None,
    ) -> None:
        """Start a new episode of string ``i``.

        With a ``seed`` the episode's generators come from ``SeedSequence(seed)``; without, from
        the next child of the string's last seed sequence (fresh entropy the first time).
        """
        config = episode_config(self.config, options)
        last = self.episodes[i]
        if seed is not None:
            root = np.random.SeedSequence(seed)
        elif last is not None:
            root = last.seed_root.spawn(1)[0]
        elif previous_root is not None:
            root = previous_root.spawn(1)[0]
        else:
            root = np.random.SeedSequence()
        generators = spawn_generators(root)
        scenario = scenario_for(config, generators)
        self.episodes[i] = _StringEpisode(config, scenario, root, generators["noise"])
        self.x[i] = 0.0
        self.mode[i] = STUCK
        self.step_index[i] = 0
        self.status[i] = kernel.STATUS_OK
        self.plant[i] = plant_parameter_vector(scenario.plant)
        self.wob_t[i], self.wob_v[i], self.wob_n[i] = knot_arrays(scenario.wob)
        self.ref_t[i], self.ref_v[i], self.ref_n[i] = knot_arrays(scenario.reference)
        self.noise_std[i] = scenario.noise_std_rad_s
        self.noise[i, self.substeps] = self._draw_noise(i, 1)[0]
        self.last_u[i] = 0.0
        self.summary[i] = 0.0
        self.records[i] = 0.0
        self.law_state[i] = 0.0
        if self.controllers:
            ctrl = self.controllers[i]
            ctrl.reset()
            if self.compiled:
                law: CompiledLaw = ctrl.compiled_law(scenario.controller_model)  # type: ignore[attr-defined]
                self.law_id = law.law_id
                self.law_params[i] = law.params
                self.law_state[i] = law.initial_state
        self.meas[i] = self.x[i]
        self.meas[i, 0::2] += scenario.noise_std_rad_s * self.noise[i, self.substeps]

    def _draw_noise(self, i: int, rows: int) -> npt.NDArray[np.float64]:
        episode = self.episodes[i]
        assert episode is not None
        if episode.scenario.noise_std_rad_s == 0.0:
            return np.zeros((rows, 4))
        return episode.noise_rng.standard_normal((rows, 4))

    # ------------------------------------------------------------------- step
    def step(self, actions: npt.NDArray[np.float64]) -> None:
        """Advance every string by one decision period under ``actions`` in [-1, 1], (num,)."""
        cfg = self.config
        if self.residual:
            np.multiply(actions, cfg.residual_scale_nm, out=self.command)
        else:
            span = cfg.max_torque_nm - cfg.min_torque_nm
            np.multiply(actions + 1.0, 0.5 * span, out=self.command)
            self.command += cfg.min_torque_nm
        s = self.substeps
        self.noise[:, 0] = self.noise[:, s]
        for i in range(self.num):
            self.noise[i, 1:] = self._draw_noise(i, s)
        if self.compiled or not self.controllers:
            self._advance(
                self.x, self.mode, self.step_index, self.status, self.plant,
                self.wob_t, self.wob_v, self.wob_n, self.ref_t, self.ref_v, self.ref_n,
                self.noise, self.noise_std, self.law_id, self.law_params, self.law_state,
                self.command, cfg.min_torque_nm, cfg.max_torque_nm, s, PLANT_DT_S,
                self.records, self.meas, self.last_u, self.summary,
            )  # fmt: skip
        else:
            self._step_python_controllers()

    def _step_python_controllers(self) -> None:
        """The slow path: call each Python controller at every plant step."""
        cfg = self.config
        n, s = self.num, self.substeps
        records1 = np.zeros((n, 1, kernel.N_RECORD))
        summary1 = np.zeros((n, kernel.N_SUMMARY))
        totals = np.zeros((n, kernel.N_SUMMARY))
        meas1 = np.zeros((n, 7))
        residual = self.command.copy()
        command = np.zeros(n)
        base = np.zeros(n)
        done = np.zeros(n)
        for j in range(s):
            for i in range(n):
                episode = self.episodes[i]
                assert episode is not None
                meas = self.x[i].copy()
                meas[0::2] += self.noise_std[i] * self.noise[i, j]
                t = self.step_index[i] * PLANT_DT_S
                ref = episode.scenario.reference.value(t)
                base[i] = float(self.controllers[i].torque(meas, ref, PLANT_DT_S))
                command[i] = base[i] + residual[i] if math.isfinite(base[i]) else math.nan
            ok = self.status == kernel.STATUS_OK
            self._advance(
                self.x, self.mode, self.step_index, self.status, self.plant,
                self.wob_t, self.wob_v, self.wob_n, self.ref_t, self.ref_v, self.ref_n,
                self.noise[:, j : j + 2], self.noise_std, LAW_NONE, self.law_params,
                self.law_state, command, cfg.min_torque_nm, cfg.max_torque_nm, 1, PLANT_DT_S,
                records1, meas1, self.last_u, summary1,
            )  # fmt: skip
            records1[:, 0, kernel.REC_BASE_TORQUE] = base
            self.records[:, j] = records1[:, 0]
            totals[ok] += summary1[ok]
            done[ok] += 1
        self.meas[:] = meas1
        self.summary[:, kernel.SUM_TRACKING] = totals[:, kernel.SUM_TRACKING] / np.maximum(done, 1)
        self.summary[:, kernel.SUM_VARIATION] = totals[:, kernel.SUM_VARIATION]
        self.summary[:, kernel.SUM_STUCK] = totals[:, kernel.SUM_STUCK] / np.maximum(done, 1)

    # ---------------------------------------------------------------- outputs
    def observations(self) -> npt.NDArray[np.float32]:
        """Scaled measured observations, (num, obs_size) float32, clipped to the bounds."""
        n = self.num
        raw = np.empty((n, self.obs_size))
        raw[:, :7] = self.meas
        raw[:, 7] = self.reference_now()
        raw[:, 8] = self.last_u
        if self.residual:
            raw[:, 9] = self.records[:, -1, kernel.REC_BASE_TORQUE]
            raw[:, 10] = self.law_state[:, 3]
        raw *= self._obs_scale
        np.nan_to_num(raw, copy=False, nan=0.0)
        np.clip(raw, -OBS_BOUND, OBS_BOUND, out=raw)
        return raw.astype(np.float32)

    def reference_now(self) -> npt.NDArray[np.float64]:
        """Reference bit speed of each string at its current time, rad/s."""
        out = np.empty(self.num)
        for i in range(self.num):
            episode = self.episodes[i]
            assert episode is not None
            out[i] = episode.scenario.reference.value(self.step_index[i] * PLANT_DT_S)
        return out

    def time_s(self) -> npt.NDArray[np.float64]:
        """Current simulated time of each string, s."""
        return self.step_index * PLANT_DT_S
