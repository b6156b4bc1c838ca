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
    UncertaintyReading,
    WobProfile,
    knot_arrays,
    profile_value,
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
    reading: UncertaintyReading = "plant" if config.uncertainty_reading == "plant" else "controller"
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
    noise_out: npt.NDArray[np.float64] | None  # where the step's noise is drawn; None: no noise
    actions_clipped: int = 0

    @property
    def duration_s(self) -> float:
        """Episode length, s, rounded down to the plant step (so that a time compares exactly)."""
        return round(self.config.episode_s / PLANT_DT_S) * PLANT_DT_S


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
        # Noise is drawn in blocks: row noise_pos is the current measurement's, the rows after
        # it the next steps'. A block holds several decision periods (fewer for big batches).
        periods = max(1, min(2000, 200_000 // n) // s)
        self.noise = np.zeros((n, periods * s + 1, 4))
        self.noise_pos = np.zeros(n, dtype=np.int64)
        self.noise_std = np.zeros(n)
        self.law_id = LAW_NONE
        self.law_params = np.zeros((n, N_LAW_PARAMS))
        self.law_state = np.zeros((n, N_LAW_STATE))
        self.command = np.zeros(n)
        self.records = np.zeros((n, s, kernel.N_RECORD))
        self.last_u = np.zeros(n)
        self.report = np.zeros((n, kernel.N_REPORT))
        self.obs = np.zeros((n, self.obs_size), dtype=np.float32)
        self.episodes: list[_StringEpisode | None] = [None] * n
        self._obs_scale = np.empty(self.obs_size)
        self._obs_scale[:7] = 1.0 / state_scales()
        self._obs_scale[7] = 1.0 / SPEED_SCALE_RAD_S
        self._obs_scale[8:] = 1.0 / config.torque_scale_nm
        if self.residual:
            self._obs_scale[N_STATE_OBS + 1] = 1.0 / SPEED_SCALE_RAD_S
        # Action to command torque: residual_scale * a, or min + (a + 1) / 2 * (max - min).
        span = config.max_torque_nm - config.min_torque_nm
        self._action_gain = config.residual_scale_nm if self.residual else 0.5 * span
        self._action_offset = 0.0 if self.residual else config.min_torque_nm + 0.5 * span
        self._args: tuple[Any, ...] | None = None
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
        noise_out = self.noise[i, 1:] if scenario.noise_std_rad_s > 0 else None
        self.episodes[i] = _StringEpisode(config, scenario, root, generators["noise"], noise_out)
        self.noise[i] = 0.0
        if noise_out is not None:
            generators["noise"].standard_normal(out=self.noise[i, 0])
            generators["noise"].standard_normal(out=noise_out)
        self.noise_pos[i] = 0
        self.x[i] = 0.0
        self.mode[i] = STUCK
        self.step_index[i] = 0
        self.status[i] = kernel.STATUS_OK
        self.plant[i] = plant_parameter_vector(scenario.plant)
        self.wob_t[i], self.wob_v[i], self.wob_n[i] = knot_arrays(scenario.wob)
        self.ref_t[i], self.ref_v[i], self.ref_n[i] = knot_arrays(scenario.reference)
        self.noise_std[i] = scenario.noise_std_rad_s
        self.last_u[i] = 0.0
        self.command[i] = 0.0
        self.records[i] = 0.0
        self.law_state[i] = 0.0
        if self.controllers:
            ctrl = self.controllers[i]
            ctrl.reset()
            if self.compiled:
                law: CompiledLaw = ctrl.compiled_law(scenario.controller_model)  # type: ignore[attr-defined]
                if law.law_id != self.law_id:
                    self.law_id = law.law_id
                    self._args = None
                self.law_params[i] = law.params
                self.law_state[i] = law.initial_state
        ref = scenario.reference.value(0.0)
        x0 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        kernel.write_observation(
            self.obs[i], self.measurement(i), ref, 0.0, 0.0, self.law_state[i, 3], self._obs_scale
        )
        self.report[i] = 0.0
        kernel.write_report(
            self.report[i], x0, STUCK, 0.0, ref, 0.0, scenario.wob.initial_n, 0.0,
            self.law_state[i], float(kernel.STATUS_OK),
        )  # fmt: skip

    def measurement(self, i: int) -> npt.NDArray[np.float64]:
        """The measured state of string ``i`` now: true state plus its speed noise, (7,)."""
        meas = self.x[i].copy()
        meas[0::2] += self.noise_std[i] * self.noise[i, self.noise_pos[i]]
        return meas

    def _refill_noise(self) -> None:
        """Start a new noise block for the strings whose block cannot hold the next period."""
        s = self.substeps
        rows = self.noise.shape[1]
        if self.num == 1:
            if self.noise_pos[0] + s < rows:
                return
            refill = [0]
        else:
            refill = np.flatnonzero(self.noise_pos + s >= rows).tolist()
        for i in refill:
            episode = self.episodes[i]
            assert episode is not None
            self.noise[i, 0] = self.noise[i, self.noise_pos[i]]
            self.noise_pos[i] = 0
            if episode.noise_out is not None:
                episode.noise_rng.standard_normal(out=episode.noise_out)

    # ------------------------------------------------------------------- step
    def step(self, actions: npt.NDArray[np.float64]) -> None:
        """Advance every string by one decision period under ``actions`` in [-1, 1], (num,).

        Strings whose status is not OK (diverged, or paused by the vector env while it resets
        them) stay where they are.
        """
        if self.num == 1:
            self.command[0] = float(actions[0]) * self._action_gain + self._action_offset
        else:
            np.multiply(actions, self._action_gain, out=self.command)
            self.command += self._action_offset
        self._refill_noise()
        if self.compiled or not self.controllers:
            self._advance(*self._kernel_args())
        else:
            self._step_python_controllers()

    def _kernel_args(self) -> tuple[Any, ...]:
        """The kernel's arguments: the batch's arrays (updated in place) and its constants."""
        if self._args is None:
            cfg = self.config
            self._args = (
                self.x, self.mode, self.step_index, self.status, self.plant,
                self.wob_t, self.wob_v, self.wob_n, self.ref_t, self.ref_v, self.ref_n,
                self.noise, self.noise_pos, self.noise_std, self.law_id, self.law_params,
                self.law_state, self.command, cfg.min_torque_nm, cfg.max_torque_nm,
                self.substeps, PLANT_DT_S, self.records, self.last_u, self.report,
                self._obs_scale, self.obs,
            )  # fmt: skip
        return self._args

    def _step_python_controllers(self) -> None:
        """The slow path: call each Python controller at every plant step."""
        cfg = self.config
        n = self.num
        records1 = np.zeros((n, 1, kernel.N_RECORD))
        totals = np.zeros((n, 3))
        residual = self.command.copy()
        command = np.zeros(n)
        base = np.zeros(n)
        done = np.zeros(n)
        terms = slice(kernel.REP_TRACKING, kernel.REP_STUCK_FRACTION + 1)
        for j in range(self.substeps):
            for i in range(n):
                t = self.step_index[i] * PLANT_DT_S
                ref = profile_value(self.ref_t[i], self.ref_v[i], self.ref_n[i], t)
                torque = self.controllers[i].torque(self.measurement(i), ref, PLANT_DT_S)
                base[i] = float(torque)
                command[i] = base[i] + residual[i] if math.isfinite(base[i]) else math.nan
            ok = self.status == kernel.STATUS_OK
            self._advance(
                self.x, self.mode, self.step_index, self.status, self.plant,
                self.wob_t, self.wob_v, self.wob_n, self.ref_t, self.ref_v, self.ref_n,
                self.noise, self.noise_pos, self.noise_std, LAW_NONE, self.law_params,
                self.law_state, command, cfg.min_torque_nm, cfg.max_torque_nm, 1, PLANT_DT_S,
                records1, self.last_u, self.report, self._obs_scale, self.obs,
            )  # fmt: skip
            records1[ok, 0, kernel.REC_BASE_TORQUE] = base[ok]
            self.records[:, j] = records1[:, 0]
            totals[ok] += self.report[ok, terms]
            done[ok] += 1
        self.report[:, kernel.REP_TRACKING] = totals[:, 0] / np.maximum(done, 1)
        self.report[:, kernel.REP_VARIATION] = totals[:, 1]
        self.report[:, kernel.REP_STUCK_FRACTION] = totals[:, 2] / np.maximum(done, 1)
        if self.residual:  # the kernel saw no base law: put the Python controllers' torque in
            moved = done > 0
            self.report[moved, kernel.REP_BASE_TORQUE] = base[moved]
            self.obs[moved, 9] = np.clip(base[moved] * self._obs_scale[9], -OBS_BOUND, OBS_BOUND)

    # ---------------------------------------------------------------- outputs
    def observations(self) -> npt.NDArray[np.float32]:
        """Scaled measured observations, (num, obs_size) float32 (a copy)."""
        return self.obs.copy()
