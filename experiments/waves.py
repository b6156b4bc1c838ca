"""``drill-gym waves``: the torsional waves of the field string and what each controller does
with them.

The field string (``DrillStringField-v0``) carries torsional waves at ``c = sqrt(G / rho)``
(2,788 m/s in the Well B pipe) between the top drive and the bit; a stick-slip cycle is the
string's lowest mode with the top drive held (top clamped, bit free), whose period is about
``4 L / c`` for a uniform pipe. This study puts numbers and pictures to that:

1. **The strings** (:func:`string_table`): per depth, the pipe length, the wave's one-way and
   round-trip travel times ``L / c`` and ``2 L / c``, the pipe impedance ``Z = J sqrt(G rho)``,
   the stick-slip period ``2 pi / w_ss`` (top clamped, bit free), the period with the bit stuck
   and the same numbers of the 4-DOF equivalent the paper's controllers are written on
   (:func:`drill_env.modes.lumped_equivalent`), beside the paper's own 4-DOF plant; and the
   cycle period the stiff speed loop actually shows there (:func:`cycle_period_s`).
2. **The runs** (:func:`record_run`): every controller, with each observation mode it can use,
   on one stick-slip-prone scenario (default 2,500 m, 150 kN, 60 rpm, nominal friction) with
   the true state of every node read at every decision (``env.unwrapped.string_state()``);
   the stick-slip severity, stuck fraction and RMSE over the last ``window`` seconds, the
   cycle period, and for the linear speed loops the reflection coefficient ``|r|`` their top
   drive presents to a wave at the stick-slip frequency.
3. **What the 4-DOF equivalent's mismatch costs** (:func:`equivalent_table`): the same
   controller (same gains, same 4-DOF model, same actuator, sensors and noise) on the 4-DOF
   equivalent itself (``DrillString-v0`` with ``parameters=lumped_equivalent(string)``) and on
   the distributed string it stands for.

The recorded runs (the stiff loop at each depth of table 1, every controller of table 3, each
controller and scenario of table 4) are the items of a study on the sweep runner
(:class:`WavesStudy`, :mod:`experiments.sweep`): serial by default, on Ray with ``--workers``,
kept in a results database with ``--results`` and resumed with ``--resume`` (runs read back
keep no node history: no figures then). Tables 1 and 2 are computed directly.

Outputs (``--out``, default ``results/waves``): ``waves.json`` (the three tables) and, under
``figures/``, ``field_response.png`` (bit speed, top-drive speed and surface torque of every
run) and ``field_space_time_<run>.png`` (node speed and element torque along the depth
against time, over the last stick-slip cycles).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import gymnasium as gym
import numpy as np
import numpy.typing as npt

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
from baselines.registry import family_members, needs_full_state
from baselines.string_modes import reflection_coefficient, string_modes, top_drive_impedance
from drill_env.control import controller_names, make_controller
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    with_measured_depth,
)
from drill_env.evaluation import ZeroAction, rollout
from drill_env.metrics import STEADY_SEVERITY, episode_metrics_from_samples, stick_slip_severity
from drill_env.modes import (
    lumped_equivalent,
    natural_frequencies_hz,
    pipe_impedance,
    pipe_travel_time_s,
)
from drill_env.parameters import PLANT_DT_S, PRESETS, DrillStringParameters
from drill_env.scenarios import WobProfile
from experiments.arguments import SEED_HIGH, ArgumentParser, names_type, output_folder
from experiments.field import (
    COMPARE_POINTS,
    FIELD_CONDITIONS,
    FIELD_ENV,
    OBSERVATIONS,
    PAPER_ENV,
    FieldCase,
    file_label,
    observations_of,
    run_label,
)
from experiments.paths import output_file
from experiments.plots import color_of, new_figure, save_figure, suptitle
from experiments.results_db import Fields, Flag, Name, Number, Schema
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    RunnerSpec,
    Task,
    TaskResult,
    item_tasks,
)
from experiments.tables import Column, markdown_table, write_json

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "RECORD_DT_S",
    "RunRecord",
    "StringHistory",
    "WavesSpec",
    "WavesStudy",
    "cycle_period_s",
    "equivalent_table",
    "main",
    "record_run",
    "reflection_table",
    "run_waves",
    "space_time_figure",
    "string_response_figure",
    "string_table",
    "waves_task",
]

RECORD_DT_S: Final = 0.02
"""Decision period of the recorded runs, s: the node states are read every 20 ms (the
controllers still act at every 1 ms plant step)."""
DEFAULT_DEPTHS_M: Final = (1_500.0, 2_500.0, 4_000.0)
"""Depths of the string table, m."""
WINDOW_S: Final = 50.0
"""Analysis window at the end of each run, s (as ``drill-gym map`` on the field string)."""
TASK_RUNS: Final = 1
"""Default items per task: a recorded run is a task of its own."""
SPACE_TIME_S: Final = 12.0
"""Length of the space-time figures, s (two stick-slip cycles at 2,500 m)."""
RESPONSE_S: Final = 30.0
"""Length of the response figure, s."""
ACTUATOR: Final = {
    "actuator_dead_time_s": 0.02,
    "actuator_lag_s": 0.02,
    "torque_rate_limit_nm_per_s": 100e3,
    "max_torque_nm": 50_800.0,
}
"""The field env's top drive, given to ``DrillString-v0`` when it runs the 4-DOF equivalent."""


@dataclass(frozen=True)
class StringHistory:
    """The true state of every node of a field string at every decision of one run.

    Attributes:
        time_s: Time of each sample, (m,), s.
        node_depth_m: Depth of each node, (n,), m (node 0: the top drive, n - 1: the bit).
        speed_rad_s: Node speeds, (m, n), rad/s.
        torque_nm: Element torques, (m, n - 1), N m (column 0: the surface torque).
        reference_rad_s: Reference bit speed, (m,), rad/s.
        pipe_length_m: Length of the drill pipe (the depth of the BHA's top), m.
        wave_speed_m_s: Torsional wave speed in the pipe, m/s.
    """

    time_s: npt.NDArray[np.float64]
    node_depth_m: npt.NDArray[np.float64]
    speed_rad_s: npt.NDArray[np.float64]
    torque_nm: npt.NDArray[np.float64]
    reference_rad_s: npt.NDArray[np.float64]
    pipe_length_m: float
    wave_speed_m_s: float

    @property
    def bit_speed_rad_s(self) -> npt.NDArray[np.float64]:
        """Bit speed, (m,), rad/s."""
        return self.speed_rad_s[:, -1]

    @property
    def top_drive_speed_rad_s(self) -> npt.NDArray[np.float64]:
        """Top-drive speed, (m,), rad/s."""
        return self.speed_rad_s[:, 0]

    @property
    def surface_torque_nm(self) -> npt.NDArray[np.float64]:
        """Torque at the top of the string, (m,), N m."""
        return self.torque_nm[:, 0]

    def window(self, start_s: float, end_s: float | None = None) -> StringHistory:
        """The samples with ``start_s <= time_s < end_s``."""
        keep = self.time_s >= start_s
        if end_s is not None:
            keep &= self.time_s < end_s
        return StringHistory(
            self.time_s[keep],
            self.node_depth_m,
            self.speed_rad_s[keep],
            self.torque_nm[keep],
            self.reference_rad_s[keep],
            self.pipe_length_m,
            self.wave_speed_m_s,
        )


@dataclass(frozen=True)
class RunRecord:
    """One recorded run: its node history and its numbers over the analysis window.

    Attributes:
        label: Controller and observation mode (``soft_speed (surface)``).
        history: The node states at every decision.
        metrics: Over the window: ``stick_slip_severity``, ``stuck_fraction``, ``rmse``,
            ``mean_bit_speed_rad_s``, the cycle periods of the bit and the top drive, the top
            drive's lowest and highest speed, the fastest speed of any node and its depth; and
            ``diverged``.
    """

    label: str
    history: StringHistory
    metrics: dict[str, Any]


def cycle_period_s(
    signal: npt.ArrayLike, dt_s: float, shortest_s: float = 0.3, longest_s: float = 30.0
) -> float | None:
    """The period of the strongest oscillation of ``signal`` (sampled every ``dt_s``): the
    shortest lag between ``shortest_s`` and ``longest_s`` at which its autocorrelation has a
    peak of at least 80 % of its highest one there (so a cycle of two unequal slips reads as
    the time between sticks, not as the pair); ``None`` when the signal hardly oscillates (no
    peak above 0.3 of the zero-lag value).

    Args:
        signal: Samples, (m,).
        dt_s: Sampling period, s.
        shortest_s: Shortest period looked for, s.
        longest_s: Longest period looked for, s (at most half the record).
    """
    x = np.asarray(signal, dtype=np.float64)
    x = x - x.mean()
    energy = float(np.dot(x, x))
    if x.size < 4 or energy <= 1e-12 * max(x.size, 1):
        return None
    n = x.size
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n] / energy
    lo = max(1, int(round(shortest_s / dt_s)))
    hi = min(n // 2, int(round(longest_s / dt_s)))
    if hi <= lo + 1:
        return None
    lags = np.arange(lo, hi)
    inner = acf[lo:hi]
    peaks = np.flatnonzero((inner[1:-1] >= inner[:-2]) & (inner[1:-1] > inner[2:])) + 1
    if peaks.size == 0:
        return None
    highest = float(inner[peaks].max())
    if highest < 0.3:
        return None
    best = peaks[inner[peaks] >= 0.8 * highest][0]
    return float(lags[best] * dt_s)


def _case(
    depth_m: float, wob_n: float, rpm: float, condition: str, deep: bool = False
) -> FieldCase:
    """The field case at ``depth_m``; ``deep``: the same id and operating point on the whole
    ``deep_5000m`` string instead."""
    case = FieldCase(
        f"{depth_m / 1e3:g}km-{wob_n / 1e3:g}kN-{rpm:g}rpm-{condition}",
        "field_2500m",
        float(depth_m),
        WobProfile(float(wob_n)),
        float(rpm),
        FIELD_CONDITIONS[condition],
    )
    if deep:
        deep_string = DISTRIBUTED_PRESETS["deep_5000m"]
        case = dataclasses.replace(
            case, parameters="deep_5000m", measured_depth_m=deep_string.measured_depth_m
        )
    return case


def record_run(
    case: FieldCase,
    controller: str,
    observation: str,
    *,
    duration_s: float = 100.0,
    window_s: float = WINDOW_S,
    noise_std_rad_s: float = 0.05,
    seed: int = 0,
) -> RunRecord:
    """One run of ``controller`` on the field string of ``case``, the state of every node read
    at every decision (:data:`RECORD_DT_S`).

    The bit-speed metrics are taken at every plant step over the last ``window_s`` seconds
    (``env.plant_samples()``); the cycle period from the bit speed at the decisions.
    """
    kwargs = {
        **case.scenario(noise_std_rad_s).keywords(),
        "episode_s": float(duration_s),
        "base_controller": controller,
        "observation": observation,
        "control_dt_s": RECORD_DT_S,
    }
    env = gym.make(FIELD_ENV, **kwargs)
    field_env: Any = env.unwrapped
    string = case.string()
    start = duration_s - window_s
    times: list[float] = []
    speeds: list[npt.NDArray[np.float64]] = []
    torques: list[npt.NDArray[np.float64]] = []
    refs: list[float] = []
    bit: list[npt.NDArray[np.float64]] = []
    stuck: list[npt.NDArray[np.bool_]] = []
    ref_steps: list[npt.NDArray[np.float64]] = []
    torque_steps: list[npt.NDArray[np.float64]] = []
    diverged = False
    try:
        _, info = env.reset(seed=seed)
        state = field_env.string_state()
        depth = state.node_depth_m
        zero = np.zeros(1, dtype=np.float32)
        while True:
            _, _, terminated, truncated, info = env.step(zero)
            state = field_env.string_state()
            times.append(float(info["time_s"]))
            speeds.append(state.speed_rad_s)
            torques.append(state.torque_nm)
            refs.append(float(info["reference_speed_rad_s"]))
            if times[-1] > start + 1e-9:
                samples = field_env.plant_samples()
                bit.append(samples.bit_speed_rad_s.copy())
                stuck.append(samples.bit_stuck.copy())
                ref_steps.append(samples.reference_rad_s.copy())
                torque_steps.append(samples.torque_nm.copy())
            if terminated or truncated:
                diverged = bool(terminated)
                break
    finally:
        env.close()
    history = StringHistory(
        np.array(times),
        depth,
        np.array(speeds),
        np.array(torques),
        np.array(refs),
        string.pipe.length_m,
        string.pipe.wave_speed_m_s,
    )
    window = episode_metrics_from_samples(
        np.concatenate(bit),
        np.concatenate(ref_steps),
        np.concatenate(torque_steps),
        np.concatenate(stuck),
        PLANT_DT_S,
    )
    w = np.concatenate(bit)
    late = history.window(start)
    metrics = {
        "stick_slip_severity": stick_slip_severity(float(w.max()), float(w.min()), float(w.mean())),
        "stuck_fraction": float(window["stuck_fraction"]),
        "rmse": float(window["rmse"]),
        "mean_bit_speed_rad_s": float(w.mean()),
        "cycle_period_s": cycle_period_s(late.bit_speed_rad_s, RECORD_DT_S),
        "top_drive_period_s": cycle_period_s(late.top_drive_speed_rad_s, RECORD_DT_S),
        "top_drive_min_rad_s": float(late.top_drive_speed_rad_s.min()),
        "top_drive_max_rad_s": float(late.top_drive_speed_rad_s.max()),
        "fastest_node_rad_s": float(late.speed_rad_s.max()),
        "fastest_node_depth_m": float(depth[int(np.argmax(late.speed_rad_s.max(axis=0)))]),
        "diverged": diverged,
    }
    return RunRecord(
        run_label({"controller": controller, "observation": observation}), history, metrics
    )


# ------------------------------------------------------------------------------- tables
def _string_row(
    name: str, string: DistributedStringParameters | DrillStringParameters
) -> dict[str, Any]:
    """The wave numbers of one string (a 4-DOF plant is its own "equivalent")."""
    if isinstance(string, DistributedStringParameters):
        eq = lumped_equivalent(string)
        first, second = natural_frequencies_hz(string, 2, top="clamped", bit="free")
        stuck = natural_frequencies_hz(string, 1, top="clamped", bit="stuck")[0]
        travel = pipe_travel_time_s(string)
        pipe: float | None = string.pipe.length_m
    else:
        eq = string
        first, second = 1.0 / string_modes(string, "clamped", "free").periods_s[:2]
        stuck = 1.0 / string_modes(string, "clamped", "stuck").periods_s[0]
        travel = math.sqrt(string.J_pi / string.k_pi)
        pipe = None
    eq_free = string_modes(eq, "clamped", "free").periods_s
    return {
        "string": name,
        "pipe_length_m": pipe,
        "one_way_s": travel,
        "round_trip_s": 2.0 * travel,
        "impedance_nm_s_rad": pipe_impedance(string),
        "stick_slip_period_s": 1.0 / first,
        "second_mode_period_s": 1.0 / second,
        "stuck_bit_period_s": 1.0 / stuck,
        "four_dof_second_mode_period_s": float(eq_free[1]),
        "four_dof_stuck_bit_period_s": float(string_modes(eq, "clamped", "stuck").periods_s[0]),
    }


def string_table(depths_m: Sequence[float]) -> list[dict[str, Any]]:
    """The wave numbers of ``field_2500m`` at each depth, of ``deep_5000m`` and of the paper's
    4-DOF plant ``zribi2024``: one-way and round-trip travel times along the pipe (s), the pipe
    impedance (N m s/rad), the periods of the lowest two modes with the top drive held and the
    bit free (the first is the stick-slip period) and of the lowest with the bit stuck (s), and
    the second clamped-top, free-bit period and the stuck-bit period of the 4-DOF equivalent
    (:func:`drill_env.modes.lumped_equivalent`; for ``zribi2024`` its own)."""

    rows = [
        _string_row(f"field_2500m at {d:,.0f} m", with_measured_depth("field_2500m", d))
        for d in depths_m
    ]
    rows.append(_string_row("deep_5000m at 5,000 m", DISTRIBUTED_PRESETS["deep_5000m"]))
    rows.append(_string_row("zribi2024 (the paper's 4-DOF plant)", PRESETS["zribi2024"]))
    return rows


def reflection_table(string: DistributedStringParameters) -> list[dict[str, Any]]:
    """The top drive each speed loop makes, seen by a torsional wave at the string's
    stick-slip frequency ``w_ss``: ``Z_td = kp + c_dt + i (w J_dt - ki / w)`` and the reflection
    coefficient ``r = (Z - Z_td) / (Z + Z_td)`` (``|r| = 1``: the wave goes back down whole,
    ``0``: it is absorbed). For ``z_torque`` with a perfect inner loop the drive gives way at
    ``dT / z`` behind the high-pass of its running mean, ``Z_td = z (1 + 1 / (i w tau))``.
    """
    rows = []
    for name in family_members("speed_loop", tuned=False):
        try:
            tuning = make_controller(name).tuning(string)  # type: ignore[attr-defined]
        except ValueError as err:
            rows.append({"controller": name, "note": str(err)})
            continue
        w = tuning.stick_slip_rad_s
        if name == "z_torque":
            z_td = tuning.z * (1.0 + 1.0 / (1j * w * tuning.tau_mean_s))
        else:
            z_td = top_drive_impedance(
                w,
                tuning.kp,
                tuning.ki,
                string.top_drive_inertia_kg_m2,
                string.damping.top_drive_nm_s_rad,
            )
        r = reflection_coefficient(z_td, tuning.pipe_impedance)
        rows.append(
            {
                "controller": name,
                "kp_nm_s_rad": tuning.kp,
                "ki_nm_rad": tuning.ki,
                "z_nm_s_rad": tuning.z,
                "drive_impedance_abs_nm_s_rad": abs(z_td),
                "reflection_abs": abs(r),
                "note": "",
            }
        )
    return rows


def equivalent_table(
    cases: Sequence[FieldCase],
    controllers: Sequence[str],
    *,
    duration_s: float = 100.0,
    window_s: float = WINDOW_S,
    noise_std_rad_s: float = 0.05,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Each controller on the 4-DOF equivalent of each case's string and on the string itself,
    with the full state measured, the same noise on the speeds, the field env's top drive
    (dead time, lag, rate limit, torque limit) and no torque or telemetry noise in both: the
    stick-slip severity, stuck fraction and cycle period (none below a severity of
    :data:`STEADY_SEVERITY`) over the last ``window_s`` seconds.

    On the 4-DOF plant the controller's model is the equivalent too, so the laws are the same
    functions of the same numbers: only the plant differs. (The speed loops are tuned from their
    model's modes, which differ between the two: this is a test of the SMCs.)
    """

    rows = []
    for case in cases:
        eq = lumped_equivalent(case.string())
        for name in controllers:
            out: dict[str, Any] = {"scenario": case.id, "controller": name}
            for key, env_id, kwargs in (
                (
                    "equivalent",
                    PAPER_ENV,
                    {
                        "parameters": eq,
                        "wob_n": case.wob.initial_n,
                        "reference_speed_rad_s": case.reference_speed_rad_s,
                        **ACTUATOR,
                    },
                ),
                (
                    "string",
                    FIELD_ENV,
                    {
                        **case.scenario(noise_std_rad_s, "exact").keywords(),
                        "observation": "state",
                        "torque_noise_std_nm": 0.0,
                        "telemetry_noise_std_rad_s": 0.0,
                    },
                ),
            ):
                env = gym.make(
                    env_id,
                    **{
                        "randomize": False,
                        **kwargs,
                        "noise_std_rad_s": noise_std_rad_s,
                        "base_controller": name,
                        "episode_s": duration_s,
                        "control_dt_s": 0.5,
                    },
                )
                try:
                    trace = rollout(env, ZeroAction(), seed)
                finally:
                    env.close()
                late = trace.time_s >= duration_s - window_s
                w = trace.bit_speed_rad_s[late]
                severity = stick_slip_severity(float(w.max()), float(w.min()), float(w.mean()))
                out[f"{key}_severity"] = severity
                out[f"{key}_stuck_fraction"] = float(trace.bit_stuck[late].mean())
                # the cycle of a run that turns steadily is that of its ripples: left out
                steady = severity < STEADY_SEVERITY
                out[f"{key}_period_s"] = None if steady else cycle_period_s(w[::20], 0.02)
            rows.append(out)
    return rows


def waves_task(jobs: Sequence[Mapping[str, Any]]) -> TaskResult:
    """A task of the sweep runner: each of ``jobs`` (its item key, its kind and arguments) run
    in turn. Kinds: ``string`` (the stiff loop's metrics on a string of table 1, seed 0),
    ``run`` (a controller's metrics of table 3; its node history in the extras, by item) and
    ``equivalent`` (a row of table 4)."""
    records: dict[str, dict[str, Any]] = {}
    histories: dict[str, StringHistory] = {}
    for job in jobs:
        item = str(job["item"])
        depth_m, wob_n, rpm, condition = job["case"]
        case = _case(depth_m, wob_n, rpm, condition, deep=bool(job.get("deep", False)))
        if job["kind"] == "equivalent":
            records[item] = equivalent_table(
                [case],
                [job["controller"]],
                duration_s=job["duration_s"],
                window_s=job["window_s"],
                seed=job["seed"],
            )[0]
            continue
        run = record_run(
            case,
            job["controller"],
            job["observation"],
            duration_s=job["duration_s"],
            window_s=job["window_s"],
            seed=job["seed"],
        )
        if job["kind"] == "string":
            records[item] = dict(run.metrics)
        else:
            records[item] = {"label": run.label, **run.metrics}
            histories[item] = run.history
    return TaskResult(records, histories or None)


@dataclass(frozen=True)
class WavesStudy:
    """The study on the sweep runner: one item per recorded run, ``string/<k>`` (the stiff
    loop on the k-th string of table 1), ``run/<k>/<controller>/<observation>`` (table 3) and
    ``equivalent/<k>/<controller>`` (the k-th scenario of table 4).

    Attributes:
        settings: The command's settings.
        task_runs: Runs per task.
    """

    settings: WavesSpec
    task_runs: int = TASK_RUNS

    @property
    def name(self) -> str:
        """The sweep's name."""
        return "waves"

    def controllers(self) -> list[str]:
        """The controllers of table 3, each once, in order."""
        return list(dict.fromkeys(self.settings.controllers or controller_names()))

    def jobs(self) -> list[dict[str, Any]]:
        """Every recorded run, in the order of the tables."""
        s = self.settings
        timing = {"duration_s": s.duration_s, "window_s": s.window_s}
        jobs: list[dict[str, Any]] = []
        depths = [*s.depths_m, s.depths_m[-1]]
        for k, depth in enumerate(depths):
            jobs.append(
                {
                    "item": f"string/{k}",
                    "kind": "string",
                    "case": [depth, s.wob_n, s.rpm, s.condition],
                    "deep": k == len(s.depths_m),
                    "controller": "stiff_pi",
                    "observation": "surface",
                    "seed": 0,
                    **timing,
                }
            )
        case = [s.depth_m, s.wob_n, s.rpm, s.condition]
        names = self.controllers()
        k = 0
        for name in names:
            for obs in observations_of(name, s.observations):
                jobs.append(
                    {
                        "item": f"run/{k}/{name}/{obs}",
                        "kind": "run",
                        "case": case,
                        "controller": name,
                        "observation": obs,
                        "seed": s.seed,
                        **timing,
                    }
                )
                k += 1
        smcs = [n for n in names if needs_full_state(n)]
        if not s.no_equivalent and smcs:
            cases = [[d, w * 1e3, r, s.condition] for w, r in COMPARE_POINTS for d in s.depths_m]
            for k, scenario in enumerate(cases):
                for name in smcs:
                    jobs.append(
                        {
                            "item": f"equivalent/{k}/{name}",
                            "kind": "equivalent",
                            "case": scenario,
                            "controller": name,
                            "seed": s.seed,
                            **timing,
                        }
                    )
        return jobs

    def spec(self) -> dict[str, Any]:
        """Everything the results depend on."""
        s = self.settings
        return {
            "controllers": self.controllers(),
            "observations": list(s.observations),
            "depth_m": s.depth_m,
            "depths_m": list(s.depths_m),
            "wob_n": s.wob_n,
            "rpm": s.rpm,
            "condition": s.condition,
            "duration_s": s.duration_s,
            "window_s": s.window_s,
            "seed": s.seed,
            "equivalent": not s.no_equivalent,
            "record_dt_s": RECORD_DT_S,
        }

    def items(self) -> list[str]:
        """Every item key."""
        return [j["item"] for j in self.jobs()]

    def record_schema(self, item: str) -> Schema:
        """A run's metrics (numbers, ``None``: not defined, and ``diverged``), with its label
        in table 3; a row of table 4."""
        if item.startswith("equivalent/"):
            return Fields({"scenario": Name(), "controller": Name()}, rest=Number())
        named = {"label": Name()} if item.startswith("run/") else {}
        return Fields({**named, "diverged": Flag()}, rest=Number())

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """The missing runs in tasks of :attr:`task_runs`."""
        wanted = set(missing)
        jobs = [j for j in self.jobs() if j["item"] in wanted]
        return item_tasks("waves", waves_task, "jobs", jobs, self.task_runs)


STRING_COLUMNS: Final = (
    Column("string", "string", align="left"),
    Column("pipe_length_m", "pipe (m)", "{:,.0f}"),
    Column("one_way_s", "L/c (s)", "{:.2f}"),
    Column("round_trip_s", "2L/c (s)", "{:.2f}"),
    Column("impedance_nm_s_rad", "Z (N m s/rad)", "{:,.0f}"),
    Column("stick_slip_period_s", "T1: stick-slip period (s)", "{:.2f}"),
    Column("second_mode_period_s", "T2: second mode (s)", "{:.2f}"),
    Column("stuck_bit_period_s", "bit stuck (s)", "{:.2f}"),
    Column("four_dof_second_mode_period_s", "4-DOF equivalent T2 (s)", "{:.2f}"),
    Column("four_dof_stuck_bit_period_s", "4-DOF equivalent, bit stuck (s)", "{:.2f}"),
    Column("stiff_pi_cycle_s", "stiff_pi cycle (s)", "{:.2f}"),
)
RUN_COLUMNS: Final = (
    Column("label", "controller", align="left"),
    Column("stick_slip_severity", "severity", "{:.2f}"),
    Column("stuck_fraction", "stuck fraction", "{:.3f}"),
    Column("rmse", "RMSE (rad/s)", "{:.2f}"),
    Column("mean_bit_speed_rad_s", "mean bit speed (rad/s)", "{:.2f}"),
    Column("cycle_period_s", "bit cycle (s)", "{:.2f}"),
    Column("top_drive_period_s", "top-drive cycle (s)", "{:.2f}"),
    Column("top_drive_min_rad_s", "top drive, min (rad/s)", "{:.2f}"),
    Column("top_drive_max_rad_s", "top drive, max (rad/s)", "{:.2f}"),
    Column("fastest_node_rad_s", "fastest node (rad/s)", "{:.1f}"),
    Column("fastest_node_depth_m", "at depth (m)", "{:,.0f}"),
)
REFLECTION_COLUMNS: Final = (
    Column("controller", "controller", align="left"),
    Column("kp_nm_s_rad", "kp (N m s/rad)", "{:,.0f}"),
    Column("ki_nm_rad", "ki (N m/rad)", "{:,.0f}"),
    Column("z_nm_s_rad", "z (N m s/rad)", "{:,.0f}"),
    Column("drive_impedance_abs_nm_s_rad", "|Z_td| at w_ss (N m s/rad)", "{:,.0f}"),
    Column("reflection_abs", "|r| at w_ss", "{:.3f}"),
    Column("note", "note", align="left"),
)
EQUIVALENT_COLUMNS: Final = (
    Column("scenario", "scenario", align="left"),
    Column("controller", "controller", align="left"),
    Column("equivalent_severity", "severity, 4-DOF equivalent", "{:.2f}"),
    Column("string_severity", "severity, field string", "{:.2f}"),
    Column("equivalent_stuck_fraction", "stuck, 4-DOF", "{:.3f}"),
    Column("string_stuck_fraction", "stuck, string", "{:.3f}"),
    Column("equivalent_period_s", "cycle, 4-DOF (s)", "{:.2f}"),
    Column("string_period_s", "cycle, string (s)", "{:.2f}"),
)


# ---------------------------------------------------------------------------- command line
def _depth_option(**kwargs: Any) -> dict[str, Any]:
    return option(low=300.0, high=10_000.0, unit="m", metavar="M", **kwargs)


@dataclass(frozen=True)
class WavesSpec:
    """Settings of ``drill-gym waves`` (each field is the option of the same name)."""

    controllers: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=names_type(controller_names, "controller"), metavar="NAME", default_text="all"
        ),
    )
    """controllers to run, by registered name"""
    observations: tuple[str, ...] = field(
        default=OBSERVATIONS, metadata=option(choices=OBSERVATIONS)
    )
    """observation modes of the speed loops (the paper's controllers: state only)"""
    depth_m: float = field(default=2_500.0, metadata=_depth_option(flag="--depth"))
    """depth of the runs, m"""
    depths_m: tuple[float, ...] = field(
        default=DEFAULT_DEPTHS_M, metadata=_depth_option(flag="--depths")
    )
    """depths of the string table and the 4-DOF comparison, m"""
    wob_n: float = field(
        default=150e3,
        metadata=option(low=0.0, high=1e6, open_low=True, unit="N", metavar="N", flag="--wob"),
    )
    """weight on bit of the runs, N"""
    rpm: float = field(
        default=60.0, metadata=option(low=0.0, high=500.0, open_low=True, unit="rpm", metavar="RPM")
    )
    """reference bit speed of the runs, rpm"""
    condition: str = field(default="nominal", metadata=option(choices=tuple(FIELD_CONDITIONS)))
    """friction and mud damping of the string"""
    duration_s: float = field(
        default=100.0,
        metadata=option(low=1.0, high=1e4, unit="s", metavar="S", aliases=("--duration",)),
    )
    """length of each run from rest, s (a multiple of 0.02 s)"""
    window_s: float = field(
        default=WINDOW_S,
        metadata=option(
            low=0.0, high=1e4, open_low=True, unit="s", metavar="S", aliases=("--window",)
        ),
    )
    """analysis window at the end of each run, s"""
    seed: int = field(default=0, metadata=option(low=0, high=SEED_HIGH))
    """reset seed of every run (it drives the noise)"""
    out: Path = field(
        default=Path("results/waves"), metadata=option(parse=output_folder, metavar="DIR")
    )
    """output folder"""
    no_equivalent: bool = False
    """skip table 4 (the paper's controllers on their 4-DOF equivalent)"""
    no_plots: bool = False
    """write no figures"""
    no_progress: bool = False
    """no progress lines"""

    def __post_init__(self) -> None:
        if self.window_s > self.duration_s:
            raise ValueError(
                f"--window: {self.window_s:g} is out of range: allowed <= --duration-s"
            )
        steps = self.duration_s / RECORD_DT_S
        if abs(steps - round(steps)) > 1e-6:
            raise ValueError(
                f"--duration-s: {self.duration_s:g} is not a multiple of {RECORD_DT_S:g} s"
            )
        bha = DISTRIBUTED_PRESETS["field_2500m"].bha_length_m
        for d in (self.depth_m, *self.depths_m):
            if d <= bha:
                raise ValueError(f"--depth: {d:g} is out of range: allowed > BHA length {bha} m")


DESCRIPTION: Final = f"""\
The torsional waves of the field string ({FIELD_ENV}) and what each controller does with
them: 1. the strings (travel times, impedance, mode periods, per --depths); 2. the speed loops'
top drive as a wave sees it (reflection coefficient); 3. every controller at --depth, --wob,
--rpm and --condition (severity, cycles, fastest node); 4. the paper's controllers on their
4-DOF equivalent against the string. Prints the tables; writes waves.json and figures/ into
--out. Tables and figures explained: docs/reports/field-string.md.

example: drill-gym waves --controllers stiff_pi soft_speed --depth 4000 --out results/waves-4km
"""


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym waves", DESCRIPTION, WavesSpec, RunnerSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym waves``: run, print the tables, write ``waves.json`` and the figures."""
    args = _parser().parse_args(argv)
    return run_waves(spec_from_args(WavesSpec, args), spec_from_args(RunnerSpec, args))


def run_waves(spec: WavesSpec, runner: RunnerSpec | None = None) -> int:
    """Run the study of ``spec`` on ``runner`` (default: serially), print the tables, write
    ``waves.json`` and the figures."""
    runner = runner or RunnerSpec()
    start = time.perf_counter()
    case = _case(spec.depth_m, spec.wob_n, spec.rpm, spec.condition)
    study = WavesStudy(spec, runner.task_size or TASK_RUNS)
    if not spec.no_progress:
        print(f"waves: {len(study.items())} recorded runs", file=sys.stderr)
    outcome = runner.run(study, spec.out / "waves.sqlite", progress=not spec.no_progress)
    records = outcome.records
    strings = string_table(spec.depths_m)
    for k, row in enumerate(strings[: len(spec.depths_m) + 1]):
        row["stiff_pi_cycle_s"] = records[f"string/{k}"]["cycle_period_s"]
    reflections = reflection_table(case.string())
    run_items = [i for i in study.items() if i.startswith("run/")]
    run_rows = [records[i] for i in run_items]
    equivalent = [records[i] for i in study.items() if i.startswith("equivalent/")]
    histories: dict[str, StringHistory] = {}
    for extras in outcome.extras.values():
        histories.update(extras)
    runs = [
        RunRecord(
            records[i]["label"], histories[i], {k: v for k, v in records[i].items() if k != "label"}
        )
        for i in run_items
        if i in histories
    ]
    out = spec.out
    out.mkdir(parents=True, exist_ok=True)
    print(f"1. The strings (stiff_pi cycle at {spec.wob_n / 1e3:g} kN, {spec.rpm:g} rpm, "
          f"{spec.condition}):\n")  # fmt: skip
    print(markdown_table(strings, STRING_COLUMNS))
    print(f"\n2. The speed loops' top drive at the stick-slip frequency of {case.id}:\n")
    print(markdown_table(reflections, REFLECTION_COLUMNS))
    print(
        f"\n3. Every controller on {case.id}, last {spec.window_s:g} s of {spec.duration_s:g} s:\n"
    )
    print(markdown_table(run_rows, RUN_COLUMNS))
    if equivalent:
        print("\n4. The paper's controllers on their 4-DOF equivalent and on the string:\n")
        print(markdown_table(equivalent, EQUIVALENT_COLUMNS))
    written = [
        write_json(
            {
                "scenario": case.id,
                "duration_s": spec.duration_s,
                "window_s": spec.window_s,
                "strings": strings,
                "reflections": reflections,
                "runs": run_rows,
                "equivalent": equivalent,
            },
            out / "waves.json",
            indent=2,
        )
    ]
    if not spec.no_plots and run_items and len(runs) < len(run_items):
        print("no figures: runs read from the results file keep no node history (rerun "
              "without --resume for the figures)")  # fmt: skip
    elif not spec.no_plots and runs:
        written += write_figures(runs, case, out, spec.duration_s)
    print(
        f"\n{len(run_rows)} recorded runs in {time.perf_counter() - start:.1f} s; wrote "
        f"{len(written)} files to {out}/"
    )
    return 0


def write_figures(
    runs: Sequence[RunRecord], case: FieldCase, out: Path, duration_s: float
) -> list[Path]:
    """``field_response.png`` and one ``field_space_time_<run>.png`` per run, in the
    ``figures`` folder of the output folder ``out``."""

    title = (
        f"{case.measured_depth_m:,.0f} m of field_2500m, WOB {case.wob.initial_n / 1e3:g} kN, "
        f"{case.reference_rpm:g} rpm, {case.condition.name} friction"
    )
    histories = {r.label: r.history.window(duration_s - RESPONSE_S) for r in runs}
    paths = [
        save_figure(
            string_response_figure(histories, f"{title}: last {RESPONSE_S:g} s of each run"),
            output_file(out, "figures", "field_response.png"),
        )
    ]
    for r in runs:
        fig = space_time_figure(r.history.window(duration_s - SPACE_TIME_S), f"{r.label}, {title}")
        name = f"field_space_time_{file_label(r.label)}.png"
        paths.append(save_figure(fig, output_file(out, "figures", name)))
    return paths


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())


# ------------------------------------------------------------ the field string's waves
def string_response_figure(
    histories: Mapping[str, StringHistory], title: str = "", *, ncols: int = 5
) -> Figure:
    """Bit speed (with the reference), top-drive speed and surface torque against time, one
    column of three panels per run, up to ``ncols`` runs per row; one speed axis for every
    speed panel and one torque axis for every torque panel, so the runs compare at a glance.

    Args:
        histories: Run label -> node history (:class:`experiments.waves.StringHistory`).
        title: Figure title.
        ncols: Runs per row.

    Raises:
        ValueError: if ``histories`` is empty.
    """
    from matplotlib.lines import Line2D

    if not histories:
        raise ValueError("histories is empty: nothing to plot")
    n = len(histories)
    ncols = max(1, min(ncols, n))
    groups = math.ceil(n / ncols)
    fig = new_figure(3.3 * ncols + 1.0, 5.6 * groups + 1.0)
    grid = np.asarray(fig.subplots(3 * groups, ncols, squeeze=False, sharex=True))
    speed_axes: list[Axes] = []
    torque_axes: list[Axes] = []
    rows = (
        ("bit speed (rad/s)", "bit"),
        ("top-drive speed (rad/s)", "top"),
        ("surface torque (kN m)", "torque"),
    )
    for k, (label, history) in enumerate(histories.items()):
        g, col = divmod(k, ncols)
        color = color_of(label, k)
        for r, (ylabel, what) in enumerate(rows):
            ax = grid[3 * g + r, col]
            t = history.time_s
            if what == "bit":
                ax.plot(t, history.reference_rad_s, color="k", ls=(0, (4, 2)), lw=1.0)
                ax.plot(t, history.bit_speed_rad_s, color=color, lw=1.3)
                ax.set_title(label, fontsize=10)
            elif what == "top":
                ax.plot(t, history.reference_rad_s, color="k", ls=(0, (4, 2)), lw=1.0)
                ax.plot(t, history.top_drive_speed_rad_s, color=color, lw=1.3)
            else:
                ax.plot(t, history.surface_torque_nm / 1e3, color=color, lw=1.3)
            (torque_axes if what == "torque" else speed_axes).append(ax)
            ax.grid(True, alpha=0.3)
            ax.ticklabel_format(axis="x", useOffset=False)
            if col == 0:
                ax.set_ylabel(ylabel, fontsize=9)
            if r == 2:
                ax.tick_params(labelbottom=True)
                ax.set_xlabel("time (s)", fontsize=9)
    for group in (speed_axes, torque_axes):
        lows = [a.get_ylim()[0] for a in group]
        highs = [a.get_ylim()[1] for a in group]
        for a in group:
            a.set_ylim(min(lows), max(highs))
    for ax in grid.ravel()[3 * n :]:
        ax.set_visible(False)
    for k in range(n, groups * ncols):
        g, col = divmod(k, ncols)
        for r in range(3):
            grid[3 * g + r, col].set_visible(False)
    fig.legend(
        handles=[Line2D([], [], color="k", ls=(0, (4, 2)), lw=1.0, label="reference bit speed")],
        loc="outside lower center",
        fontsize=10,
    )
    suptitle(fig, title)
    return fig


def _slip_onsets(history: StringHistory, threshold_rad_s: float = 0.05) -> npt.NDArray[np.float64]:
    """Times at which the bit starts to turn again after sticking, s (at most one per travel
    time of a wave from the bit to the surface)."""
    moving = history.bit_speed_rad_s > threshold_rad_s
    starts = history.time_s[np.flatnonzero(moving[1:] & ~moving[:-1]) + 1]
    gap = float(history.node_depth_m[-1]) / history.wave_speed_m_s
    kept: list[float] = []
    for t in starts:  # one per cycle: a release within one travel time of the last is the same
        if not kept or t - kept[-1] > gap:
            kept.append(float(t))
    return np.array(kept)


def space_time_figure(history: StringHistory, title: str = "") -> Figure:
    """The torsional waves along the string: node speed (top) and the torque each element
    carries (bottom) as colour maps over time (x) and depth (y, the surface at the top).

    The dashed white line is the top of the BHA. Each dotted line starts at the bit when it
    breaks free and climbs at the pipe's wave speed ``c``: where the colours change along it,
    the release wave is travelling up the string; it reaches the top drive ``D / c`` later.

    Args:
        history: The node history of one run (:class:`experiments.waves.StringHistory`),
            typically its last stick-slip cycles.
        title: Figure title.

    Raises:
        ValueError: if the history has fewer than two samples.
    """
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    if history.time_s.size < 2:
        raise ValueError("history has fewer than two samples: nothing to plot")
    fig = new_figure(10.0, 7.6)
    ax_w, ax_t = fig.subplots(2, 1, sharex=True, sharey=True)
    t = history.time_s
    depth = history.node_depth_m
    mid = 0.5 * (depth[1:] + depth[:-1])
    speed_high = max(float(np.percentile(history.speed_rad_s, 99.5)), 1e-3)
    mesh_w = ax_w.pcolormesh(
        t, depth, history.speed_rad_s.T, shading="nearest", cmap="viridis",
        norm=Normalize(0.0, speed_high), rasterized=True,
    )  # fmt: skip
    torque = history.torque_nm.T / 1e3
    mesh_t = ax_t.pcolormesh(
        t, mid, torque, shading="nearest", cmap="magma",
        norm=Normalize(float(np.percentile(torque, 0.5)), float(np.percentile(torque, 99.5))),
        rasterized=True,
    )  # fmt: skip
    bottom = float(depth[-1])
    handles: list[Any] = [
        Line2D([], [], color="white", ls="--", lw=1.4, label="top of the BHA"),
    ]
    onsets = _slip_onsets(history)
    travel = bottom / history.wave_speed_m_s
    for ax in (ax_w, ax_t):
        ax.axhline(history.pipe_length_m, color="white", ls="--", lw=1.4)
        for t0 in onsets:
            ax.plot([t0, t0 + travel], [bottom, 0.0], color="white", ls=":", lw=1.6)
        ax.set_xlim(float(t[0]), float(t[-1]))
        ax.set_ylim(bottom, 0.0)
        ax.set_ylabel("depth (m)")
    if onsets.size:
        handles.append(
            Line2D(
                [],
                [],
                color="white",
                ls=":",
                lw=1.6,
                label=f"from the bit's release at c = {history.wave_speed_m_s:,.0f} m/s: "
                f"at the surface {travel:.2f} s later",
            )  # fmt: skip
        )
    ax_w.set_title("node speed")
    ax_t.set_title("torque carried by the string")
    ax_t.set_xlabel("time (s)")
    ax_t.ticklabel_format(axis="x", useOffset=False)
    fig.colorbar(mesh_w, ax=ax_w, label="speed (rad/s)", extend="max")
    fig.colorbar(mesh_t, ax=ax_t, label="torque (kN m)", extend="both")
    legend = fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=10)
    legend.get_frame().set_facecolor("0.45")
    for text in legend.get_texts():
        text.set_color("white")
    suptitle(fig, title)
    return fig
