"""A batch of drill strings stepped together: the engine under the single and vector envs.

:class:`StringBatch` owns the per-string arrays that the compiled kernel advances, the
per-string scenarios and random generators, and the base controllers. The single env is a
batch of one, so the vector env reproduces it bit for bit. The strings are all 4-DOF plants
(``DrillString-v0``) or all distributed strings (``DrillStringField-v0``), possibly of different
lengths (padded to the longest the configuration allows).
"""

from __future__ import annotations

import copy
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
import numpy.typing as npt

from drill_env import coupled_chain, kernel
from drill_env._cache import announce_compilation
from drill_env.actuator import lag_factor
from drill_env.chain import CHAIN_WORK_ROWS, chain_parameter_length, chain_parameter_vector
from drill_env.control import (
    CompiledController,
    CompiledLaw,
    Controller,
    Measurement,
    compile_law,
    resolve_controller,
)
from drill_env.distributed import (
    DistributedStringParameters,
    section_element_counts,
    with_measured_depth,
)
from drill_env.friction import STUCK
from drill_env.layout import (
    CH_ACTUATOR,
    CH_HOLD,
    CH_TELEMETRY,
    ESTIMATE_FIELDS,
    F_BASE_TORQUE,
    F_COMMAND,
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
    N_FIXED_SOURCES,
    N_INTS,
    N_MEASUREMENT,
    N_PLANT_PARAMS,
    N_PROFILES,
    N_RECORD,
    N_REPORT,
    N_SCALARS,
    N_STATE,
    OBS_BOUND,
    PROF_REF_T,
    PROF_REF_V,
    PROF_WOB_T,
    PROF_WOB_V,
    REC_X0,
    REP_LAW_ERROR,
    REP_LAW_GAIN,
    REP_RESIDUAL_SQUARED,
    REP_STEPS,
    REP_STUCK_STEPS,
    REP_TORQUE_SQUARED,
    REP_TRACKING_SUM,
    REP_VARIATION,
    STATE_NAMES,
    STATUS_OK,
    ObservationField,
    chain_state_fields,
    observation_fields,
    observation_scales,
    observation_sources,
)
from drill_env.limits import MAX_BATCH_BYTES
from drill_env.modes import probe_nodes
from drill_env.options import EnvConfig, episode_config, steps_of
from drill_env.parameters import PLANT_DT_S, plant_parameter_vector
from drill_env.scenarios import (
    MAX_KNOTS,
    FieldRandomization,
    Scenario,
    carried_seed_sequence,
    knot_arrays,
    profile_value,
    spawn_generators,
)
from drill_env.sensors import reset_channel, telemetry_buffer_size
from drill_env.validation import printable, shown

__all__ = ["StringBatch", "node_count"]

PARALLEL_THRESHOLD: Final = 64
"""Batches at least this large use numba's threads."""

_SUMS: Final = slice(REP_TRACKING_SUM, REP_RESIDUAL_SQUARED + 1)
"""The report's reward sums (accumulated over the plant steps of the slow path)."""
assert tuple(range(1, 5)) == (REP_VARIATION, REP_STUCK_STEPS, REP_STEPS, REP_TORQUE_SQUARED)


def node_count(parameters: DistributedStringParameters) -> int:
    """Nodes of the chain of a distributed string."""
    return 1 + sum(section_element_counts(parameters))


def _noise_rows(num: int, substeps: int) -> int:
    """Rows of a string's noise block: several decision periods (fewer for big batches)."""
    periods = max(1, min(2000, 200_000 // num) // substeps)
    return periods * substeps + 1


def _check_batch_size(config: EnvConfig, num: int, max_nodes: int, chain: bool) -> None:
    """Refuse, before anything is allocated, a batch whose per-string arrays would exceed
    :data:`drill_env.limits.MAX_BATCH_BYTES` (``num_envs`` is named: the keywords are valid)."""
    s = config.substeps
    state = 2 * max_nodes - 1 if chain else N_STATE
    node_cols = max_nodes if chain else 1
    period = steps_of(config.telemetry_period_s) if config.telemetry_period_s else 0
    delay = steps_of(config.telemetry_delay_s)
    floats = (
        s * N_RECORD  # records
        + _noise_rows(num, s) * 6  # speed and sensor noise blocks
        + 2 * telemetry_buffer_size(period, delay)
        + steps_of(config.actuator_dead_time_s) + 1
        + (CHAIN_WORK_ROWS + 1) * node_cols
        + (chain_parameter_length(max_nodes) if chain else N_PLANT_PARAMS)
        + 2 * state + N_FIXED_SOURCES + N_PROFILES * MAX_KNOTS
        + N_INTS + N_SCALARS + N_MEASUREMENT + N_CHANNEL + N_REPORT + 8
    )  # fmt: skip
    per_string = 8 * floats
    if num * per_string > MAX_BATCH_BYTES:
        most = max(1, MAX_BATCH_BYTES // per_string)
        raise ValueError(
            f"num_envs = {num} is out of range: allowed at most {most} strings with these "
            f"keywords ({per_string / 2**20:.3g} MiB of arrays each, at most "
            f"{MAX_BATCH_BYTES / 2**30:g} GiB in all)"
        )


def _real_torque(value: object) -> float | None:
    """``value`` as a float when it is one real number (not a bool), else None."""
    if isinstance(value, np.ndarray):
        if value.size != 1 or value.dtype.kind not in "fiu" or isinstance(value, np.ma.MaskedArray):
            return None
        value = value.reshape(()).item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except (OverflowError, ValueError, TypeError):
        return math.inf


def _max_nodes(config: EnvConfig) -> int:
    """The most nodes a string of this configuration can have (its deepest string)."""
    string = config.string()
    count = node_count(string)
    if config.randomize and isinstance(config.randomization, FieldRandomization):
        deepest = max(config.randomization.measured_depth_range_m)
        count = max(count, node_count(with_measured_depth(string, deepest)))
    return count


@dataclass
class _StringEpisode:
    config: EnvConfig
    scenario: Scenario
    seed_root: np.random.bit_generator.ISpawnableSeedSequence  # spawns the next episode's
    noise_rng: np.random.Generator
    noise_out: npt.NDArray[np.float64] | None  # where the step's noise is drawn; None: no noise
    sensor_rng: np.random.Generator
    sensor_out: npt.NDArray[np.float64] | None  # the same for the surface torque and telemetry
    node_rng: np.random.Generator | None  # node-speed noise of a distributed string's state
    duration_s: float = 0.0  # the episode's length (config.duration_s, kept for the hot path)
    actions_clipped: int = 0


class _EstimateObservation(NamedTuple):
    """Where the estimate entries of ``observation="estimate"`` come from and go: the law's
    state slots, the source columns, the observation columns and their scales."""

    slots: list[int]
    sources: list[int]
    columns: list[int]
    scales: npt.NDArray[np.float64]


def _estimate_observation(
    config: EnvConfig,
    law: CompiledLaw | None,
    first_source: int,
    fields: tuple[ObservationField, ...],
) -> _EstimateObservation:
    """The estimate entries of the observation (none unless ``observation="estimate"``).

    Raises:
        ValueError: ``observation="estimate"`` with a base controller whose compiled law
            reports no observer estimate.
    """
    if config.observation != "estimate":
        return _EstimateObservation([], [], [], np.zeros(0))
    named: dict[str, int] = {} if law is None else dict(law.info_slots)
    if law is not None:
        named.update((f"estimated_{STATE_NAMES[x]}", slot) for x, slot in law.estimate_slots)
    missing = [name for name, _ in ESTIMATE_FIELDS if name not in named]
    if missing:
        raise ValueError(
            f"observation = 'estimate' needs a base controller whose compiled law runs a state "
            f"observer (a speed loop or a sliding-mode law: soft_speed, z_torque_tuned, "
            f"proposed, ...): base_controller = {shown(config.base_controller)} reports no "
            f"{', '.join(missing)}"
        )
    sources = [first_source + k for k in range(len(ESTIMATE_FIELDS))]
    columns = [next(c for c, f in enumerate(fields) if f.source == s) for s in sources]
    scales = observation_scales(tuple(fields[c] for c in columns), config.torque_scale_nm)
    return _EstimateObservation([named[n] for n, _ in ESTIMATE_FIELDS], sources, columns, scales)


class StringBatch:
    """``num`` drill strings sharing one :class:`EnvConfig` and one base controller type."""

    def __init__(self, config: EnvConfig, num: int) -> None:
        self.config = config
        self.num = num
        self.substeps = config.substeps
        self.residual = config.residual
        self.chain = config.distributed
        self.max_nodes = _max_nodes(config) if self.chain else 4
        _check_batch_size(config, num, self.max_nodes, self.chain)
        state_size = 2 * self.max_nodes - 1 if self.chain else N_STATE
        state_fields = chain_state_fields(self.max_nodes) if self.chain else None
        self.fields = observation_fields(
            self.residual,
            config.observation,
            config.telemetry,
            *((state_fields,) if state_fields is not None else ()),
        )
        # bit="rgd": a string with axial elements and the RGD bit (drill_env.coupled_chain);
        # its weight on bit and rate of penetration close the observation.
        bit = config.bit_parameters() if self.chain else None  # type: ignore[attr-defined]
        self.coupled = bit is not None
        self._bit = bit
        extra = N_FIXED_SOURCES + state_size
        if self.coupled:
            self.fields += (
                ObservationField("weight_on_bit_n", extra, "force"),
                ObservationField("rate_of_penetration_m_s", extra + 1, "rop"),
            )
        estimate_source = extra + (2 if self.coupled else 0)
        if config.observation == "estimate":  # filled from the law's state after each call
            self.fields += tuple(
                ObservationField(name, estimate_source + k, kind)
                for k, (name, kind) in enumerate(ESTIMATE_FIELDS)
            )
        self.obs_size = len(self.fields)
        controller = resolve_controller(config.base_controller)
        self.controllers: list[Controller] = []
        law: CompiledLaw | None = None
        if controller is not None:
            self.controllers = [controller] + [copy.deepcopy(controller) for _ in range(num - 1)]
            if isinstance(controller, CompiledController):
                # The law for the env's own model of the string: the vectors' sizes of the
                # batch (a law's may depend on the kind of model, not on its values).
                law = compile_law(
                    controller,
                    config.fixed_scenario().controller_model,
                    config.torque_limits,
                    config.measurement_channel(),
                )
        self.compiled = law is not None
        # What a Python controller cannot read by name (drill_env.control.Measurement).
        self._missing_signals = Measurement.missing_signals(config.measurement_channel())
        self._info_slots = () if law is None else law.info_slots
        self._estimate_slots = () if law is None else law.estimate_slots
        self._estimate_keys = [
            (f"estimated_{STATE_NAMES[x]}", f"estimate_error_{STATE_NAMES[x]}", REC_X0 + x, slot)
            for x, slot in self._estimate_slots
        ]
        self.reports_law_slots = bool(self._info_slots or self._estimate_slots)
        """Whether the compiled law names state slots the env reports (:meth:`law_info`)."""
        self._estimate_obs = _estimate_observation(config, law, estimate_source, self.fields)
        n, s = num, self.substeps
        # Noise is drawn in blocks: row noise_pos is the current measurement's, the rows after
        # it the next steps'. A block holds several decision periods (fewer for big batches).
        rows = _noise_rows(n, s)
        period = steps_of(config.telemetry_period_s) if config.telemetry_period_s else 0
        delay = steps_of(config.telemetry_delay_s)
        node_cols = self.max_nodes if self.chain else 1
        self.arrays = kernel.BatchArrays(
            x=np.zeros((n, state_size)),
            ints=np.zeros((n, N_INTS), dtype=np.int64),
            scalars=np.zeros((n, N_SCALARS)),
            plant=np.zeros(
                (n, chain_parameter_length(self.max_nodes) if self.chain else N_PLANT_PARAMS)
            ),
            work=np.zeros((n, CHAIN_WORK_ROWS, node_cols) if self.chain else (n, 1, 1)),
            probes=np.tile(np.arange(4, dtype=np.int64), (n, 1)),
            profiles=np.zeros((n, N_PROFILES, MAX_KNOTS)),
            noise=np.zeros((n, rows, 4)),
            sensor_noise=np.zeros((n, rows, 2)),
            node_noise=np.zeros((n, node_cols)),
            law_params=np.zeros((n, 1 if law is None else law.params.size)),
            law_state=np.zeros((n, 1 if law is None else law.initial_state.size)),
            measurement=np.zeros((n, N_MEASUREMENT)),
            channel=np.zeros((n, N_CHANNEL)),
            delay_line=np.zeros((n, steps_of(config.actuator_dead_time_s) + 1)),
            telemetry_buffer=np.zeros((n, telemetry_buffer_size(period, delay), 2)),
            records=np.zeros((n, s, N_RECORD)),
            report=np.zeros((n, N_REPORT)),
            sources=np.zeros((n, estimate_source + len(self._estimate_obs.slots))),
            obs=np.zeros((n, self.obs_size), dtype=np.float32),
        )
        rate = config.torque_rate_limit_nm_per_s
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
            state_mode=config.observation == "state",
            sensor_steps=steps_of(config.sensor_period_s),
            telemetry_period=period,
            telemetry_delay=delay,
            ideal_actuator=config.ideal_actuator,
            lag=lag_factor(config.actuator_lag_s, PLANT_DT_S),
            rate_step=math.inf if rate is None else rate * PLANT_DT_S,
            chain=self.chain,
        )
        self.episodes: list[_StringEpisode | None] = [None] * n
        self.end_reasons: list[str] = [""] * n
        """Why each string's episode ended early, if not by diverging ("" otherwise)."""
        self._noise_rows = rows
        self._node_noise = self.chain and config.observation == "state"
        self._compiled_loop = self.compiled or not self.controllers  # no Python controller
        self._scalars_row = self.arrays.scalars[0]  # string 0's rows (the single env's)
        self._ints_row = self.arrays.ints[0]
        # Action to command torque: residual_scale * a, or min + (a + 1) / 2 * (max - min).
        span = config.max_torque_nm - config.min_torque_nm
        self._action_gain = config.residual_scale_nm if self.residual else 0.5 * span
        self._action_offset = 0.0 if self.residual else config.min_torque_nm + 0.5 * span
        self.coupled_arrays = (
            coupled_chain.coupled_arrays(n, self.max_nodes, (extra, extra + 1))
            if self.coupled
            else None
        )
        # What the kernel's entry takes: the packed arrays (kernel.PackedArrays: the fastest
        # call), or the arrays themselves for the coupled loop.
        self._packed = None if self.coupled else kernel.PackedArrays(self.arrays)
        self._kernel_input: object = self.arrays if self._packed is None else self._packed.meta
        if self.coupled_arrays is not None:
            coupled_dispatcher = (
                coupled_chain.advance_coupled_batch_parallel
                if n >= PARALLEL_THRESHOLD
                else coupled_chain.advance_coupled_batch
            )
            entry = kernel.fast_entry(
                coupled_dispatcher, self.arrays, self.settings, self.coupled_arrays
            )
            coupled = self.coupled_arrays

            def advance(arrays: kernel.BatchArrays, settings: kernel.LoopSettings) -> None:
                entry(arrays, settings, coupled)

            self._advance: Callable[..., None] = advance
            self._coupled_entry = entry
            return
        if self.chain:
            serial, parallel = kernel.advance_chain_batch, kernel.advance_chain_batch_parallel
        else:
            serial, parallel = kernel.advance_batch, kernel.advance_batch_parallel
        dispatcher = parallel if n >= PARALLEL_THRESHOLD else serial
        with announce_compilation(*self._kernel_name()):
            self._advance = kernel.fast_entry(dispatcher, self._kernel_input, self.settings)

    def _kernel_name(self) -> tuple[str, float]:
        """What compiling this batch's kernel is called, and about how long it takes, s."""
        if self.chain:
            return "the distributed-string plant kernel", 10.0
        return "the plant kernel", 6.0

    # ------------------------------------------------------------- arrays by name
    @property
    def x(self) -> npt.NDArray[np.float64]:
        """True states, (num, 7) for the 4-DOF plant, (num, 2 n_max - 1) for distributed
        strings (zero-padded), rad/s and rad."""
        return self.arrays.x

    @property
    def status(self) -> npt.NDArray[np.int64]:
        """Run status of each string (``drill_env.layout.STATUS_*``), (num,) (a writable view)."""
        return self.arrays.ints[:, I_STATUS]

    @property
    def command(self) -> npt.NDArray[np.float64]:
        """The command torque of the last step (the residual in residual mode), (num,), N m
        (a writable view)."""
        return self.arrays.scalars[:, F_COMMAND]

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

    def nodes(self, i: int) -> int:
        """Nodes of string ``i`` (4 for the 4-DOF plant)."""
        episode = self.episodes[i]
        if not self.chain or episode is None:
            return 4
        return node_count(episode.scenario.plant)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ reset
    def reset_string(
        self,
        i: int,
        seed: int | None,
        options: dict[str, object] | None,
        previous_root: np.random.SeedSequence | None = None,
    ) -> None:
        """Start a new episode of string ``i``.

        With a ``seed`` the episode's generators come from ``SeedSequence(seed)``; without, from
        the next child of the string's last seed sequence (fresh entropy the first time). The
        sequences carry their hash forward (:class:`drill_env.scenarios.CarriedSeedSequence`):
        numpy's, bit for bit, at a cost that does not grow with the number of episodes.
        """
        config = episode_config(self.config, options)
        last = self.episodes[i]
        root: np.random.bit_generator.ISpawnableSeedSequence
        if seed is not None:
            root = carried_seed_sequence(np.random.SeedSequence(seed))
        elif last is not None:
            root = last.seed_root.spawn(1)[0]
        elif previous_root is not None:
            root = carried_seed_sequence(previous_root.spawn(1)[0])
        else:
            root = carried_seed_sequence(np.random.SeedSequence())
        generators = spawn_generators(root)
        scenario = config.scenario(generators)
        a = self.arrays
        if self.chain:
            n_nodes = node_count(scenario.plant)  # type: ignore[arg-type]
            if n_nodes > self.max_nodes:
                raise ValueError(
                    f"the string of this episode has {n_nodes} nodes: allowed at most "
                    f"{self.max_nodes} in this env (set the deeper string or depth range at "
                    "make)"
                )
        noise_out = a.noise[i, 1:] if scenario.noise_std_rad_s > 0 else None
        sensed = config.torque_noise_std_nm > 0 or config.telemetry_noise_std_rad_s > 0
        sensor_out = a.sensor_noise[i, 1:] if sensed else None
        node_rng = (
            generators["nodes"]
            if self.chain and config.observation == "state" and scenario.noise_std_rad_s > 0
            else None
        )
        self.episodes[i] = _StringEpisode(
            config, scenario, root, generators["noise"], noise_out, generators["sensors"],
            sensor_out, node_rng, config.duration_s,
        )  # fmt: skip
        self.end_reasons[i] = ""
        a.noise[i] = 0.0
        if noise_out is not None:
            generators["noise"].standard_normal(out=a.noise[i, 0])
            generators["noise"].standard_normal(out=noise_out)
        a.sensor_noise[i] = 0.0
        if sensor_out is not None:
            generators["sensors"].standard_normal(out=a.sensor_noise[i, 0])
            generators["sensors"].standard_normal(out=sensor_out)
        a.node_noise[i] = 0.0
        self._draw_node_noise(i)
        a.x[i] = 0.0
        a.ints[i] = 0
        a.ints[i, I_MODE] = STUCK
        a.ints[i, I_STATUS] = STATUS_OK
        if self.chain:
            a.plant[i] = chain_parameter_vector(scenario.plant, a.plant.shape[1])
            a.probes[i] = probe_nodes(scenario.plant)  # type: ignore[arg-type]
        else:
            a.plant[i] = plant_parameter_vector(scenario.plant)  # type: ignore[arg-type]
        prof = a.profiles[i]
        prof[PROF_WOB_T], prof[PROF_WOB_V], a.ints[i, I_WOB_KNOTS] = knot_arrays(scenario.wob)
        reference = knot_arrays(scenario.reference)
        prof[PROF_REF_T], prof[PROF_REF_V], a.ints[i, I_REF_KNOTS] = reference
        a.scalars[i] = 0.0
        a.scalars[i, F_NOISE_STD] = scenario.noise_std_rad_s
        a.scalars[i, F_TORQUE_NOISE_STD] = config.torque_noise_std_nm
        a.scalars[i, F_TELEMETRY_NOISE_STD] = config.telemetry_noise_std_rad_s
        a.channel[i] = 0.0
        a.delay_line[i] = 0.0
        reset_channel(a.channel[i, CH_HOLD:CH_TELEMETRY], a.channel[i, CH_TELEMETRY:CH_ACTUATOR])
        a.records[i] = 0.0
        a.law_state[i] = 0.0
        if self.controllers:
            ctrl = self.controllers[i]
            ctrl.reset()
            if self.compiled:
                law = compile_law(
                    ctrl,  # type: ignore[arg-type]
                    scenario.controller_model,
                    config.torque_limits,
                    config.measurement_channel(scenario.noise_std_rad_s),
                )
                if law.address != self.settings.law_address:
                    raise ValueError("every string of a batch must run the same compiled law")
                if (law.params.size, law.initial_state.size) != (
                    a.law_params.shape[1],
                    a.law_state.shape[1],
                ):
                    raise ValueError(
                        "every string of a batch must run a law of the same vector sizes: "
                        f"got params {law.params.size} and state {law.initial_state.size}, "
                        f"the batch has {a.law_params.shape[1]} and {a.law_state.shape[1]}"
                    )
                if (law.info_slots, law.estimate_slots) != (
                    self._info_slots,
                    self._estimate_slots,
                ):
                    raise ValueError("every string of a batch must report the same law slots")
                a.law_params[i] = law.params
                a.law_state[i] = law.initial_state
        a.report[i] = 0.0
        if self.coupled_arrays is not None:
            assert self._bit is not None
            torsion = coupled_chain.reset_coupled_string(
                self.coupled_arrays, i, scenario.plant,  # type: ignore[arg-type]
                self._bit, axial_top=config.axial_top,  # type: ignore[attr-defined]
                hook_speed_m_s=config.hook_speed_m_s,  # type: ignore[attr-defined]
                hook_stiffness_n_m=config.hook_stiffness_n_m,  # type: ignore[attr-defined]
                applied_force_n=float(prof[PROF_WOB_V, 0]),
                reference_speed_rad_s=float(prof[PROF_REF_V, 0]),
            )  # fmt: skip
            a.x[i, : torsion.shape[0]] = torsion
            out = self.coupled_arrays.out[i]
            a.sources[i, -2] = out[coupled_chain.OUT_WOB]
            a.sources[i, -1] = out[coupled_chain.OUT_ROP]
        advance = self._advance
        if self.coupled_arrays is not None:  # string i's rows of the coupled arrays too
            rows = coupled_chain.string_rows(self.coupled_arrays, i)
            entry = self._coupled_entry

            def advance(arrays: kernel.BatchArrays, settings: kernel.LoopSettings) -> None:
                entry(arrays, settings, rows)

        with announce_compilation(*self._kernel_name()):
            kernel.observe(advance, a if self._packed is None else self._packed, self.settings, i)
        if self._estimate_obs.slots:
            self._write_estimates()

    def law_info(self) -> dict[str, npt.NDArray[np.float64]]:
        """The state slots the compiled law names (:class:`drill_env.control.CompiledLaw`
        ``info_slots`` and ``estimate_slots``) after the last step, (num,) each: the named
        values, ``estimated_<state name>`` and ``estimate_error_<state name>`` (the estimate
        minus the true state at the plant step of the law's last call, from the records; 0
        before the first step, NaN for a string that did not move)."""
        if not self.reports_law_slots:
            return {}
        state = self.arrays.law_state
        info = {key: state[:, slot].copy() for key, slot in self._info_slots}
        last = self.arrays.records[:, -1]
        for estimated, error, column, slot in self._estimate_keys:
            info[estimated] = state[:, slot].copy()
            info[error] = state[:, slot] - last[:, column]
        return info

    def law_info_of(self, i: int) -> dict[str, float]:
        """:meth:`law_info` of string ``i`` as floats (the single env's hot path)."""
        if not self.reports_law_slots:
            return {}
        state = self.arrays.law_state[i].tolist()
        last = self.arrays.records[i, -1].tolist()
        info = {key: state[slot] for key, slot in self._info_slots}
        for estimated, error, column, slot in self._estimate_keys:
            info[estimated] = state[slot]
            info[error] = state[slot] - last[column]
        return info

    def coupled_info(self) -> dict[str, npt.NDArray[np.float64] | npt.NDArray[np.bool_]]:
        """With ``bit="rgd"``: the bit's ``info`` entries, (num,) each
        (:func:`drill_env.coupled_chain.coupled_info`); else nothing."""
        if self.coupled_arrays is None:
            return {}
        return coupled_chain.coupled_info(self.coupled_arrays)

    def coupled_info_of(self, i: int) -> dict[str, float | bool]:
        """:meth:`coupled_info` of string ``i`` as Python scalars."""
        return {key: value[i].item() for key, value in self.coupled_info().items()}

    def measurement(self, i: int) -> npt.NDArray[np.float64]:
        """The measurement vector of string ``i`` now (``drill_env.layout.M_*``: the measured
        state in ``state`` mode, the surface signals, the telemetry), a copy."""
        with announce_compilation("the measurement channel for Python controllers", 4.0):
            kernel.measure(self.arrays, self.settings, i)
        return self.arrays.measurement[i].copy()

    def _draw_node_noise(self, i: int) -> None:
        episode = self.episodes[i]
        if episode is not None and episode.node_rng is not None:
            episode.node_rng.standard_normal(out=self.arrays.node_noise[i])

    def _refill_noise(self) -> None:
        """Start a new noise block for the strings whose block cannot hold the next period."""
        a = self.arrays
        s = self.substeps
        rows = self._noise_rows
        position = a.ints[:, I_NOISE_POS]
        if self.num == 1:
            if position[0] + s < rows:
                return
            refill = [0]
        else:
            refill = np.flatnonzero(position + s >= rows).tolist()
        for i in refill:
            episode = self.episodes[i]
            assert episode is not None
            row = position[i]
            a.noise[i, 0] = a.noise[i, row]
            a.sensor_noise[i, 0] = a.sensor_noise[i, row]
            position[i] = 0
            if episode.noise_out is not None:
                episode.noise_rng.standard_normal(out=episode.noise_out)
            if episode.sensor_out is not None:
                episode.sensor_rng.standard_normal(out=episode.sensor_out)

    # ------------------------------------------------------------------- step
    def step(self, actions: npt.NDArray[np.float64]) -> None:
        """Advance every string by one decision period under ``actions`` in [-1, 1], (num,).

        Strings whose status is not OK (diverged, or paused by the vector env while it resets
        them) stay where they are.
        """
        scalars = self.arrays.scalars
        if self.num == 1:
            scalars[0, F_COMMAND] = float(actions[0]) * self._action_gain + self._action_offset
        else:
            scalars[:, F_COMMAND] = actions * self._action_gain + self._action_offset
        self._refill_noise()
        if self._node_noise:  # for the strings that move (not those being reset)
            for i in np.flatnonzero(self.status == STATUS_OK).tolist():
                self._draw_node_noise(i)
        if self.compiled or not self.controllers:
            self._advance(self._kernel_input, self.settings)
        else:
            self._step_python_controllers()
        if self._estimate_obs.slots:
            self._write_estimates()

    def step_one(self, action: float) -> float:
        """:meth:`step` for a batch of one under ``action`` in [-1, 1] (the single env's hot
        path: the same arithmetic, fewer Python operations); returns the command torque (the
        residual in residual mode), N m."""
        command = action * self._action_gain + self._action_offset
        self._scalars_row[F_COMMAND] = command
        if self._ints_row[I_NOISE_POS] + self.substeps >= self._noise_rows:
            self._refill_noise()
        if self._node_noise and self._ints_row[I_STATUS] == STATUS_OK:
            self._draw_node_noise(0)
        if self._compiled_loop:
            self._advance(self._kernel_input, self.settings)
        else:
            self._step_python_controllers()
        if self._estimate_obs.slots:
            self._write_estimates()
        return command

    def _write_estimates(self) -> None:
        """The observation's estimate entries (``observation="estimate"``) from the law's state
        after the last call: scaled, NaN as 0, clipped to ``+-OBS_BOUND`` like every entry."""
        a = self.arrays
        e = self._estimate_obs
        values = a.law_state[:, e.slots]
        a.sources[:, e.sources] = values
        scaled = np.nan_to_num(values * e.scales, nan=0.0, posinf=OBS_BOUND, neginf=-OBS_BOUND)
        a.obs[:, e.columns] = np.clip(scaled, -OBS_BOUND, OBS_BOUND)

    def _step_python_controllers(self) -> None:
        """The slow path: call each Python controller at every plant step, and the kernel
        for one plant step at a time with the controllers' torques as base torques."""
        a = self.arrays
        n = self.num
        one_step = self.settings._replace(n_sub=1)
        step_arrays = a._replace(records=np.zeros((n, 1, N_RECORD)))
        packed = None if self._packed is None else kernel.PackedArrays(step_arrays)
        step_input = step_arrays if packed is None else packed.meta
        sums = np.zeros((n, _SUMS.stop))
        coupled = self.coupled_arrays
        if coupled is not None:  # the bit's outputs over the whole decision, not its last step
            depth_start = coupled.out[:, coupled_chain.OUT_DEPTH].copy()
            wob_sum = np.zeros(n)
        for j in range(self.substeps):
            for i in range(n):
                t = a.ints[i, I_STEP] * PLANT_DT_S
                prof = a.profiles[i]
                ref = profile_value(prof[PROF_REF_T], prof[PROF_REF_V], a.ints[i, I_REF_KNOTS], t)
                measured = Measurement(self.measurement(i), self._missing_signals)
                value = self.controllers[i].torque(measured, ref, PLANT_DT_S)
                torque = self._base_torque(i, value)
                a.scalars[i, F_BASE_TORQUE] = torque
            self._advance(step_input, one_step)
            a.records[:, j] = step_arrays.records[:, 0]
            sums += a.report[:, _SUMS]
            if coupled is not None:
                wob_sum += coupled.out[:, coupled_chain.OUT_WOB_MEAN] * a.report[:, REP_STEPS]
        a.report[:, _SUMS] = sums
        if coupled is not None:
            self._coupled_decision_outputs(coupled, depth_start, wob_sum, sums[:, REP_STEPS])
        a.report[:, REP_LAW_ERROR] = 0.0  # a Python controller's state is its own
        a.report[:, REP_LAW_GAIN] = 0.0

    def _base_torque(self, i: int, value: object) -> float:
        """The base torque a Python controller returned, N m: a real number (a numpy scalar or
        a one-element real array too). A NaN or infinite torque ends string ``i``'s episode
        (:meth:`end_reason` names the controller); anything else raises ``TypeError``."""
        torque = value if type(value) is float else _real_torque(value)
        if torque is None:
            name = printable(type(self.controllers[i]).__name__)
            raise TypeError(
                f"base_controller {name}.torque() returned {shown(value)} "
                f"({printable(type(value).__name__)}): expected a finite real number, N m"
            )
        if not math.isfinite(torque):
            if not self.end_reasons[i]:
                name = printable(type(self.controllers[i]).__name__)
                self.end_reasons[i] = f"base_controller {name} returned {shown(torque)} N m"
            return math.nan
        return torque

    def end_reason(self, i: int) -> str:
        """Why string ``i``'s episode ended: the base controller's failure, else
        ``"diverged"``."""
        return self.end_reasons[i] or "diverged"

    def _coupled_decision_outputs(
        self,
        coupled: coupled_chain.CoupledArrays,
        depth_start: npt.NDArray[np.float64],
        wob_sum: npt.NDArray[np.float64],
        steps: npt.NDArray[np.float64],
    ) -> None:
        """The slow path's rate of penetration and mean weight on bit over the decision
        (the kernel, called one plant step at a time, gave those of the last step), and the
        observation entries that show them."""
        a = self.arrays
        out = coupled.out
        for i in np.flatnonzero(steps > 0).tolist():
            span = steps[i] * PLANT_DT_S
            out[i, coupled_chain.OUT_ROP] = (
                out[i, coupled_chain.OUT_DEPTH] - depth_start[i]
            ) / span
            out[i, coupled_chain.OUT_WOB_MEAN] = wob_sum[i] / steps[i]
            a.sources[i, -2] = out[i, coupled_chain.OUT_WOB]
            a.sources[i, -1] = out[i, coupled_chain.OUT_ROP]
            kernel.write_observation(
                a.obs[i], a.sources[i], self.settings.obs_source, self.settings.obs_scale
            )

    # ---------------------------------------------------------------- outputs
    def observations(self) -> npt.NDArray[np.float32]:
        """Scaled measured observations, (num, obs_size) float32 (a copy)."""
        return self.arrays.obs.copy()

    def reward_sums(self) -> npt.NDArray[np.float64]:
        """The last step's reward sums (the report's first columns), (num, 6)."""
        return self.arrays.report[:, _SUMS]
