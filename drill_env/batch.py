"""A batch of drill strings stepped together: the engine under the single and vector envs.

:class:`StringBatch` owns the per-string arrays that the compiled kernel advances, the
per-string scenarios and random generators, and the base controllers. The single env is a
batch of one, so the vector env reproduces it bit for bit.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env import kernel
from drill_env.control import CompiledController, CompiledLaw, Controller, resolve_controller
from drill_env.friction import STUCK
from drill_env.layout import (
    N_MEASUREMENT,
    N_PLANT_PARAMS,
    N_RECORD,
    N_REPORT,
    N_SOURCES,
    N_STATE,
    REP_LAW_ERROR,
    REP_LAW_GAIN,
    REP_RESIDUAL_SQUARED,
    REP_STEPS,
    REP_STUCK_STEPS,
    REP_TORQUE_SQUARED,
    REP_TRACKING_SUM,
    REP_VARIATION,
    SPEED_INDICES,
    STATUS_OK,
    observation_fields,
    observation_scales,
    observation_sources,
)
from drill_env.options import EnvConfig, episode_config
from drill_env.parameters import PLANT_DT_S, plant_parameter_vector
from drill_env.scenarios import MAX_KNOTS, Scenario, knot_arrays, profile_value, spawn_generators

__all__ = ["StringBatch"]

PARALLEL_THRESHOLD: Final = 64
"""Batches at least this large use numba's threads."""

_SUMS: Final = slice(REP_TRACKING_SUM, REP_RESIDUAL_SQUARED + 1)
"""The report's reward sums (accumulated over the plant steps of the slow path)."""
assert tuple(range(1, 5)) == (REP_VARIATION, REP_STUCK_STEPS, REP_STEPS, REP_TORQUE_SQUARED)


@dataclass
class _StringEpisode:
    config: EnvConfig
    scenario: Scenario
    seed_root: np.random.SeedSequence
    noise_rng: np.random.Generator
    noise_out: npt.NDArray[np.float64] | None  # where the step's noise is drawn; None: no noise
    actions_clipped: int = 0


class StringBatch:
    """``num`` drill strings sharing one :class:`EnvConfig` and one base controller type."""

    def __init__(self, config: EnvConfig, num: int) -> None:
        self.config = config
        self.num = num
        self.substeps = config.substeps
        self.residual = config.residual
        self.fields = observation_fields(self.residual)
        self.obs_size = len(self.fields)
        controller = resolve_controller(config.base_controller)
        self.controllers: list[Controller] = []
        law: CompiledLaw | None = None
        if controller is not None:
            self.controllers = [controller] + [copy.deepcopy(controller) for _ in range(num - 1)]
            if isinstance(controller, CompiledController):
                law = controller.compiled_law(None, config.torque_limits)
        self.compiled = law is not None
        n, s = num, self.substeps
        # Noise is drawn in blocks: row noise_pos is the current measurement's, the rows after
        # it the next steps'. A block holds several decision periods (fewer for big batches).
        periods = max(1, min(2000, 200_000 // n) // s)
        self.arrays = kernel.BatchArrays(
            x=np.zeros((n, N_STATE)),
            mode=np.zeros(n, dtype=np.int64),
            step_index=np.zeros(n, dtype=np.int64),
            status=np.zeros(n, dtype=np.int64),
            plant=np.zeros((n, N_PLANT_PARAMS)),
            wob_t=np.zeros((n, MAX_KNOTS)),
            wob_v=np.zeros((n, MAX_KNOTS)),
            wob_n=np.ones(n, dtype=np.int64),
            ref_t=np.zeros((n, MAX_KNOTS)),
            ref_v=np.zeros((n, MAX_KNOTS)),
            ref_n=np.ones(n, dtype=np.int64),
            noise=np.zeros((n, periods * s + 1, 4)),
            noise_pos=np.zeros(n, dtype=np.int64),
            noise_std=np.zeros(n),
            law_params=np.zeros((n, 1 if law is None else law.params.size)),
            law_state=np.zeros((n, 1 if law is None else law.initial_state.size)),
            measurement=np.zeros((n, N_MEASUREMENT)),
            command=np.zeros(n),
            base_torque=np.zeros(n),
            last_u=np.zeros(n),
            records=np.zeros((n, s, N_RECORD)),
            report=np.zeros((n, N_REPORT)),
            sources=np.zeros((n, N_SOURCES)),
            obs=np.zeros((n, self.obs_size), dtype=np.float32),
        )
        self.settings = kernel.LoopSettings(
            law_address=0 if law is None else law.address,
            error_slot=-1 if law is None else law.error_slot,
            gain_slot=-1 if law is None else law.gain_slot,
            u_min=float(config.min_torque_nm),
            u_max=float(config.max_torque_nm),
            n_sub=s,
            dt=PLANT_DT_S,
            obs_source=observation_sources(self.fields),
            obs_scale=observation_scales(self.fields, config.torque_scale_nm),
        )
        self.episodes: list[_StringEpisode | None] = [None] * n
        # Action to command torque: residual_scale * a, or min + (a + 1) / 2 * (max - min).
        span = config.max_torque_nm - config.min_torque_nm
        self._action_gain = config.residual_scale_nm if self.residual else 0.5 * span
        self._action_offset = 0.0 if self.residual else config.min_torque_nm + 0.5 * span
        dispatcher = (
            kernel.advance_batch_parallel if n >= PARALLEL_THRESHOLD else kernel.advance_batch
        )
        self._advance = kernel.fast_entry(dispatcher, self.arrays, self.settings)

    # ------------------------------------------------------------- arrays by name
    @property
    def x(self) -> npt.NDArray[np.float64]:
        """True states, (num, 7), rad/s and rad."""
        return self.arrays.x

    @property
    def status(self) -> npt.NDArray[np.int64]:
        """Run status of each string (``drill_env.layout.STATUS_*``), (num,)."""
        return self.arrays.status

    @property
    def command(self) -> npt.NDArray[np.float64]:
        """The command torque of the last step (the residual in residual mode), (num,), N m."""
        return self.arrays.command

    @property
    def records(self) -> npt.NDArray[np.float64]:
        """The last step's plant-rate records, (num, substeps, N_RECORD)
        (``drill_env.layout.REC_*``)."""
        return self.arrays.records

    @property
    def report(self) -> npt.NDArray[np.float64]:
        """The last step's report, (num, N_REPORT) (``drill_env.layout.REP_*``)."""
        return self.arrays.report

    @property
    def obs(self) -> npt.NDArray[np.float32]:
        """The current observations, (num, obs_size) (not a copy)."""
        return self.arrays.obs

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
        scenario = config.scenario(generators)
        a = self.arrays
        noise_out = a.noise[i, 1:] if scenario.noise_std_rad_s > 0 else None
        self.episodes[i] = _StringEpisode(config, scenario, root, generators["noise"], noise_out)
        a.noise[i] = 0.0
        if noise_out is not None:
            generators["noise"].standard_normal(out=a.noise[i, 0])
            generators["noise"].standard_normal(out=noise_out)
        a.noise_pos[i] = 0
        a.x[i] = 0.0
        a.mode[i] = STUCK
        a.step_index[i] = 0
        a.status[i] = STATUS_OK
        a.plant[i] = plant_parameter_vector(scenario.plant)
        a.wob_t[i], a.wob_v[i], a.wob_n[i] = knot_arrays(scenario.wob)
        a.ref_t[i], a.ref_v[i], a.ref_n[i] = knot_arrays(scenario.reference)
        a.noise_std[i] = scenario.noise_std_rad_s
        a.last_u[i] = 0.0
        a.command[i] = 0.0
        a.base_torque[i] = 0.0
        a.records[i] = 0.0
        a.law_state[i] = 0.0
        if self.controllers:
            ctrl = self.controllers[i]
            ctrl.reset()
            if self.compiled:
                law = ctrl.compiled_law(  # type: ignore[attr-defined]
                    scenario.controller_model, config.torque_limits
                )
                if law.address != self.settings.law_address:
                    raise ValueError("every string of a batch must run the same compiled law")
                a.law_params[i] = law.params
                a.law_state[i] = law.initial_state
        ref = scenario.reference.value(0.0)
        x0 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        s = self.settings
        error = a.law_state[i, s.error_slot] if s.error_slot >= 0 else 0.0
        gain = a.law_state[i, s.gain_slot] if s.gain_slot >= 0 else 0.0
        kernel.fill_sources(a.sources[i], self.measurement(i), ref, 0.0, 0.0, error)
        kernel.write_observation(a.obs[i], a.sources[i], s.obs_source, s.obs_scale)
        a.report[i] = 0.0
        kernel.write_report(
            a.report[i], x0, STUCK, 0.0, ref, 0.0, scenario.wob.initial_n, 0.0, error, gain,
            float(STATUS_OK),
        )  # fmt: skip

    def measurement(self, i: int) -> npt.NDArray[np.float64]:
        """The measured state of string ``i`` now: true state plus its speed noise, (7,)."""
        a = self.arrays
        meas = a.x[i].copy()
        meas[list(SPEED_INDICES)] += a.noise_std[i] * a.noise[i, a.noise_pos[i]]
        return meas

    def _refill_noise(self) -> None:
        """Start a new noise block for the strings whose block cannot hold the next period."""
        a = self.arrays
        s = self.substeps
        rows = a.noise.shape[1]
        if self.num == 1:
            if a.noise_pos[0] + s < rows:
                return
            refill = [0]
        else:
            refill = np.flatnonzero(a.noise_pos + s >= rows).tolist()
        for i in refill:
            episode = self.episodes[i]
            assert episode is not None
            a.noise[i, 0] = a.noise[i, a.noise_pos[i]]
            a.noise_pos[i] = 0
            if episode.noise_out is not None:
                episode.noise_rng.standard_normal(out=episode.noise_out)

    # ------------------------------------------------------------------- step
    def step(self, actions: npt.NDArray[np.float64]) -> None:
        """Advance every string by one decision period under ``actions`` in [-1, 1], (num,).

        Strings whose status is not OK (diverged, or paused by the vector env while it resets
        them) stay where they are.
        """
        command = self.arrays.command
        if self.num == 1:
            command[0] = float(actions[0]) * self._action_gain + self._action_offset
        else:
            np.multiply(actions, self._action_gain, out=command)
            command += self._action_offset
        self._refill_noise()
        if self.compiled or not self.controllers:
            self._advance(self.arrays, self.settings)
        else:
            self._step_python_controllers()

    def _step_python_controllers(self) -> None:
        """The slow path: call each Python controller at every plant step, and the kernel
        for one plant step at a time with the controllers' torques as base torques."""
        a = self.arrays
        n = self.num
        one_step = self.settings._replace(n_sub=1)
        step_arrays = a._replace(records=np.zeros((n, 1, N_RECORD)))
        sums = np.zeros((n, _SUMS.stop))
        for j in range(self.substeps):
            for i in range(n):
                t = a.step_index[i] * PLANT_DT_S
                ref = profile_value(a.ref_t[i], a.ref_v[i], a.ref_n[i], t)
                torque = self.controllers[i].torque(self.measurement(i), ref, PLANT_DT_S)
                a.base_torque[i] = float(torque) if math.isfinite(float(torque)) else math.nan
            self._advance(step_arrays, one_step)
            a.records[:, j] = step_arrays.records[:, 0]
            sums += a.report[:, _SUMS]
        a.report[:, _SUMS] = sums
        a.report[:, REP_LAW_ERROR] = 0.0  # a Python controller's state is its own
        a.report[:, REP_LAW_GAIN] = 0.0

    # ---------------------------------------------------------------- outputs
    def observations(self) -> npt.NDArray[np.float32]:
        """Scaled measured observations, (num, obs_size) float32 (a copy)."""
        return self.arrays.obs.copy()

    def reward_sums(self) -> npt.NDArray[np.float64]:
        """The last step's reward sums (the report's first columns), (num, 6)."""
        return self.arrays.report[:, _SUMS]

    def steps_taken(self) -> npt.NDArray[np.float64]:
        """Plant steps taken in the last step by each string, (num,)."""
        return self.arrays.report[:, REP_STEPS]
