"""``drill-gym map``: the stick-slip map of a controller over WOB x reference speed.

Drilling engineers read stick-slip as a map: for every pair of weight on bit and rotary speed,
does the bit turn steadily or stick and slip? Each cell of the grid is one run of the closed
loop from rest (bit stuck) for ``duration_s`` seconds with a constant WOB and a constant
reference bit speed, the controller running inside the plant loop at every 1 ms step. After
the start-up transient, over the last ``window_s`` seconds (40 s by default, longer than the
13-36 s stick-slip periods of docs/specification.md section 6), two numbers are kept per cell:

* ``stick_slip_severity = (max x7 - min x7) / (2 mean x7)`` of the true bit speed (the
  section 4 definition, 1.0 when the bit does not turn on average); about 1 or more is
  stick-slip, near 0 steady rotation;
* ``stuck_fraction``: the share of plant steps with the bit stuck.

All cells run together as the strings of one native vector env (``gym.make_vec``: one
compiled call per step, numba threads), in decision periods of up to 1 s; only running
maxima, minima and sums over the window are kept
(:class:`drill_env.metrics.WindowStatistics`), so memory does not grow with the run length.

Command line (see ``drill-gym map --help``)::

    drill-gym map --controllers stiff_pi soft_speed z_torque proposed --out results/

writes per controller ``stick_slip_map_<name>.csv`` (columns ``wob_n``,
``reference_speed_rad_s``, ``stick_slip_severity``, ``stuck_fraction``) and
``stick_slip_map_<name>.png`` (severity and stuck-fraction heatmaps), and with several
controllers also ``stick_slip_maps.png`` with all of them side by side.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple, Protocol, TypeAlias

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from tqdm import tqdm

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
from agents.policy import load_policy
from drill_env.control import controller_names
from drill_env.distributed import DISTRIBUTED_PRESETS, with_measured_depth
from drill_env.evaluation import reset_each
from drill_env.limits import MAX_REFERENCE_RAD_S, MAX_WOB_N
from drill_env.metrics import STICK_SLIP_SEVERITY, WindowStatistics
from drill_env.options import REALISM_LEVELS, realism_keywords
from drill_env.parameters import PLANT_DT_S, PRESETS
from drill_env.scenarios import RPM
from drill_env.validation import printable, shown
from experiments.arguments import (
    BASE_SEED_HIGH,
    ArgumentParser,
    check_output_option,
    output_folder,
)
from experiments.controllers import (
    CONTROLLERS_OPTION_HELP,
    controller_type,
    refuse_on_ray,
    user_controller_errors,
)
from experiments.field import (
    ENV_IDS,
    FIELD_ENV,
    OBSERVATIONS,
    PAPER_ENV,
    is_field,
    observations_of,
)
from experiments.paths import output_path
from experiments.plots import (
    SEVERITY_LIMIT,
    cell_edges,
    new_figure,
    save_figure,
)
from experiments.results_db import Fields, Near, Number, Schema, Values, exactly
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    MAP_TASK_CELLS,
    RunnerSpec,
    SweepOutcome,
    Task,
    TaskResult,
    agent_fingerprint,
    check_controllers,
    check_observations,
    check_task_size,
    chunks,
)
from experiments.tables import write_csv

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "CSV_COLUMNS",
    "DEFAULT_REALISM",
    "MapPolicy",
    "MapRun",
    "MapSpec",
    "MapStudy",
    "StickSlipMap",
    "compute_map",
    "grid_values",
    "main",
    "map_figure",
    "map_key",
    "map_realism",
    "map_rows_task",
    "maps_figure",
    "stick_slip",
    "write_map_csv",
]

CSV_COLUMNS: Final = ("wob_n", "reference_speed_rad_s", "stick_slip_severity", "stuck_fraction")
"""Columns of the map CSV, one row per cell."""

DEFAULT_WINDOW_S: Final = 40.0
"""Analysis window at the end of each run, s (longer than one stick-slip period)."""
FIELD_WINDOW_S: Final = 50.0
"""Analysis window on the field string, s: at least four of its longest stick-slip cycles
(4-11 s at 1.5-5 km)."""
MAX_CHUNK_STEPS: Final = 1000
"""Plant steps per compiled call (1 s): bounds the memory of the per-step records."""
UNSTABLE_SEVERITY: Final = STICK_SLIP_SEVERITY
"""A cell counts as stick-slipping when its severity exceeds this or its bit ever sticks."""
DEFAULT_REALISM: Final[dict[str, str | None]] = {PAPER_ENV: "ideal", FIELD_ENV: None}
"""The level of realism (``drill_env.options.REALISM_LEVELS``) a map runs at by default:
``DrillString-v0``'s own defaults are the ``ideal`` level; ``DrillStringField-v0``'s map
keeps the env's sensors and top drive with the observation it is given, which is no level."""


def map_realism(env_id: str, realism: str | None) -> str | None:
    """The level of realism a map of ``env_id`` applies: ``None`` for the default map
    (:data:`DEFAULT_REALISM`, or no level), else ``realism``.

    Raises:
        ValueError: for an unknown env or level.
    """
    is_field(env_id)  # validates the env
    if realism is None or realism == DEFAULT_REALISM[env_id]:
        return None
    if realism not in REALISM_LEVELS:
        raise ValueError(
            f"realism = {shown(realism)} is not a known level: allowed {', '.join(REALISM_LEVELS)}"
        )
    return realism


def stick_slip(
    severity: npt.ArrayLike,
    stuck_fraction: npt.ArrayLike,
    severity_limit: float = UNSTABLE_SEVERITY,
) -> npt.NDArray[np.bool_]:
    """The stick-slip criterion of the maps: the bit stuck at some point of the window or the
    severity is above ``severity_limit``; a diverged run (NaN severity) counts as stick-slip.

    Args:
        severity: Stick-slip severity of each run over its window (NaN: diverged), any shape.
        stuck_fraction: Share of the window with the bit stuck, the same shape.
        severity_limit: Severity above which a run is in stick-slip.

    Returns:
        Whether each run is in stick-slip, the same shape.
    """
    sev = np.asarray(severity, dtype=np.float64)
    stuck = np.asarray(stuck_fraction, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        result: npt.NDArray[np.bool_] = (stuck > 0.0) | (sev > severity_limit) | np.isnan(sev)
    return result


@dataclass(frozen=True)
class StickSlipMap:
    """The stick-slip map of one controller.

    Attributes:
        controller: Registered controller name.
        wob_n: WOB of each grid row, (n_wob,), N.
        reference_speed_rad_s: Reference bit speed of each grid column, (n_speed,), rad/s.
        severity: ``(max - min) / (2 mean)`` of the bit speed over the window,
            (n_wob, n_speed); NaN where the run diverged.
        stuck_fraction: Share of the window with the bit stuck, (n_wob, n_speed); NaN where the
            run diverged.
        duration_s: Length of each run, s.
        window_s: Analysis window at the end of each run, s.
        noise_std_rad_s: Measurement noise on the speeds, rad/s.
        seed: Seed of cell 0 (cell ``i`` uses ``seed + i``).
        parameters: Plant preset name.
        wall_time_s: Wall-clock time of the simulation, s.
        env_id: The env of the runs (``DrillString-v0`` or ``DrillStringField-v0``).
        observation: The field env's observation mode the controller ran with (``None`` on
            ``DrillString-v0``).
        measured_depth_m: The field string's measured depth, m (``None`` on
            ``DrillString-v0``).
        realism: The level of realism the map ran at (``None``: the default map,
            :func:`map_realism`).
    """

    controller: str
    wob_n: npt.NDArray[np.float64]
    reference_speed_rad_s: npt.NDArray[np.float64]
    severity: npt.NDArray[np.float64]
    stuck_fraction: npt.NDArray[np.float64]
    duration_s: float
    window_s: float
    noise_std_rad_s: float
    seed: int
    parameters: str
    wall_time_s: float
    env_id: str = PAPER_ENV
    observation: str | None = None
    measured_depth_m: float | None = None
    realism: str | None = None

    @property
    def label(self) -> str:
        """The controller, with the observation mode on the field string and the level of
        realism when it is not the default: ``proposed (surface) [field]``."""
        label = self.controller
        if self.observation is not None:
            label += f" ({self.observation})"
        return label if self.realism is None else f"{label} [{self.realism}]"

    def file_stem(self) -> str:
        """``stick_slip_map_<controller>``, on the field string with the observation mode and
        the depth (``stick_slip_map_stiff_pi_surface_2500m``), and with the level of realism
        when it is not the default (``stick_slip_map_proposed_surface_2500m_field``)."""
        stem = f"stick_slip_map_{self.controller}"
        if self.observation is not None and self.measured_depth_m is not None:
            stem += f"_{self.observation}_{self.measured_depth_m:g}m"
        return stem if self.realism is None else f"{stem}_{self.realism}"

    @property
    def cells(self) -> int:
        """Number of grid cells."""
        return int(self.severity.size)

    @property
    def diverged(self) -> npt.NDArray[np.bool_]:
        """Cells whose run diverged, (n_wob, n_speed)."""
        return np.isnan(self.severity)

    def unstable(self, severity_limit: float = UNSTABLE_SEVERITY) -> npt.NDArray[np.bool_]:
        """Cells in stick-slip (:func:`stick_slip`), (n_wob, n_speed)."""
        return stick_slip(self.severity, self.stuck_fraction, severity_limit)

    def rows(self) -> list[tuple[float, float, float, float]]:
        """One ``CSV_COLUMNS`` tuple per cell, WOB-major."""
        return [
            (
                float(w),
                float(v),
                float(self.severity[i, j]),
                float(self.stuck_fraction[i, j]),
            )
            for i, w in enumerate(self.wob_n)
            for j, v in enumerate(self.reference_speed_rad_s)
        ]


def grid_values(name: str, low: float, high: float, count: int, upper: float) -> np.ndarray:
    """``count`` evenly spaced values from ``low`` to ``high``, validated.

    Args:
        name: Argument name for messages (``"wob"`` or ``"speed"``).
        low, high: Range ends (> 0, at most ``upper``); ``low < high`` unless ``count == 1``,
            when ``low <= high`` and the grid is ``[low]``.
        count: Number of values (an integer >= 1).
        upper: Largest allowed value.

    Raises:
        ValueError: naming ``--{name}-min``, ``--{name}-max`` or ``--{name}-n``.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"--{name}-n = {shown(count)} is out of range: allowed an integer >= 1")
    for end, value in (("min", low), ("max", high)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 < value <= upper):
            raise ValueError(
                f"--{name}-{end} = {shown(value)} is out of range: allowed (0, {upper:g}]"
            )
    if high < low:
        raise ValueError(
            f"--{name}-min = {shown(low)} and --{name}-max = {shown(high)}: the range is inverted "
            "(min must be <= max)"
        )
    if high == low and count > 1:
        raise ValueError(
            f"--{name}-min = --{name}-max = {shown(low)}: the range is empty; widen it or use "
            f"--{name}-n 1"
        )
    return np.linspace(low, high, int(count))


def _chunk_steps(total_steps: int) -> int:
    """The largest divisor of ``total_steps`` up to ``MAX_CHUNK_STEPS``."""
    for d in range(min(MAX_CHUNK_STEPS, total_steps), 0, -1):
        if total_steps % d == 0:
            return d
    return 1  # pragma: no cover - d = 1 always divides


class MapPolicy(Protocol):
    """A learned controller on the map (:class:`agents.policy.ResidualPolicy` is one): its
    name, the env keywords it was trained with and an SB3-style deterministic ``predict``."""

    @property
    def name(self) -> str: ...

    @property
    def env_kwargs(self) -> Mapping[str, Any]: ...

    def predict(
        self,
        observation: npt.ArrayLike,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[npt.NDArray[np.float32], Any]: ...


def compute_map(
    controller: str | MapPolicy,
    wob_n: npt.ArrayLike,
    reference_speed_rad_s: npt.ArrayLike,
    duration_s: float = 100.0,
    window_s: float = DEFAULT_WINDOW_S,
    noise_std_rad_s: float = 0.0,
    seed: int = 0,
    parameters: str | None = None,
    progress: bool = True,
    *,
    env_id: str = PAPER_ENV,
    observation: str | None = None,
    measured_depth_m: float | None = None,
    realism: str | None = None,
) -> StickSlipMap:
    """Run every (WOB, reference speed) cell from rest and measure its stick-slip.

    Args:
        controller: Registered controller name (:func:`baselines.controller_names`), or a
            learned policy (:class:`MapPolicy`, e.g. ``agents.load_policy(path)``): the cells
            then run with its env keywords and its deterministic action at every decision.
        wob_n: WOB values of the rows, N (each > 0).
        reference_speed_rad_s: Reference bit speeds of the columns, rad/s (each > 0).
        duration_s: Length of each run, s (a multiple of 0.1 s, at most 10,000 s).
        window_s: Analysis window at the end of each run, s (in (0, duration_s]).
        noise_std_rad_s: Measurement noise on the speeds, rad/s (0 for a deterministic map).
        seed: Seed of cell 0; cell ``i`` (WOB-major) is reset with ``seed + i``.
        parameters: Plant preset name: a 4-DOF one on ``DrillString-v0`` (default
            ``zribi2024``), a distributed one on ``DrillStringField-v0`` (default
            ``field_2500m``).
        progress: Show a tqdm progress bar (on stderr).
        env_id: The env of the runs (:data:`experiments.field.ENV_IDS`).
        observation: On the field string, the observation mode of the controller (``state`` or
            ``surface``; default ``state``). Without noise the surface torque and the
            telemetry are exact too; with noise they carry the env's default noise.
            With ``realism``, the level's observation (an ``observation`` that differs from
            it is an error).
        measured_depth_m: On the field string, its measured depth, m (default the preset's).
        realism: A level of ``drill_env.options.REALISM_LEVELS``: the map's env gets
            ``realism_keywords(realism)`` (the observation, the sensors with their noise,
            the telemetry and the actuator; ``noise_std_rad_s`` still sets the speed noise).
            ``None`` (the default) keeps today's map: ``DrillString-v0`` at its own defaults
            (the ``ideal`` level, which gives the same map), ``DrillStringField-v0`` at its
            own with ``observation``.

    Returns:
        The :class:`StickSlipMap`.

    Raises:
        ValueError: naming the argument that is out of range or unknown.
    """
    policy = None if isinstance(controller, str) else controller
    policy_kwargs = _policy_env_kwargs(policy, env_id) if policy is not None else {}
    if policy is not None:
        controller = policy.name
    else:
        names = controller_names()
        if controller not in names:
            raise ValueError(
                f"unknown controller {shown(controller)}: valid names are {', '.join(names)}"
            )
    assert isinstance(controller, str)
    field = is_field(env_id)
    presets = DISTRIBUTED_PRESETS if field else PRESETS
    if parameters is None:
        parameters = DEFAULTS[env_id].parameters
    if parameters not in presets:
        raise ValueError(
            f"parameters = {shown(parameters)} is not a known preset of {env_id}: {sorted(presets)}"
        )
    level = map_realism(env_id, realism)
    extra: dict[str, Any] = {} if level is None else realism_keywords(level)
    if level is not None and observation not in (None, extra["observation"]):
        raise ValueError(
            f"observation = {shown(observation)} is not that of realism = {shown(level)} "
            f"({shown(extra['observation'])}): leave it out"
        )
    trained_observation = policy_kwargs.pop("observation", None)
    if policy is not None and level is not None:
        trained = trained_observation or "state"
        if trained != extra["observation"]:
            raise ValueError(
                f"realism = {shown(level)} observes {shown(extra['observation'])} signals, model "
                f"{shown(policy.name)} was trained on {shown(trained)} ones: map it at a level that "
                "observes what it was trained on"
            )
    if field:
        observation = (
            observation
            or trained_observation
            or ("state" if level is None else extra["observation"])
        )
        if observation not in OBSERVATIONS:
            raise ValueError(
                f"observation = {shown(observation)} is not valid: allowed {', '.join(OBSERVATIONS)}"
            )
        if measured_depth_m is None:
            measured_depth_m = DISTRIBUTED_PRESETS[parameters].measured_depth_m
        with_measured_depth(parameters, measured_depth_m)  # validates the depth
        extra.update(observation=observation, measured_depth_m=float(measured_depth_m))
        if noise_std_rad_s == 0 and level is None:
            extra.update(torque_noise_std_nm=0.0, telemetry_noise_std_rad_s=0.0)
    elif (level is None and observation is not None) or measured_depth_m is not None:
        raise ValueError(
            f"observation and measured_depth_m are keywords of the field string, not of {env_id}"
        )
    wobs = np.atleast_1d(np.asarray(wob_n, dtype=np.float64))
    speeds = np.atleast_1d(np.asarray(reference_speed_rad_s, dtype=np.float64))
    for label, values, upper in (
        ("wob_n", wobs, MAX_WOB_N),
        ("reference_speed_rad_s", speeds, MAX_REFERENCE_RAD_S),
    ):
        if values.ndim != 1 or values.size == 0:
            raise ValueError(f"{label} must be a non-empty 1-D sequence, got shape {values.shape}")
        if not (np.all(np.isfinite(values)) and np.all(values > 0) and np.all(values <= upper)):
            raise ValueError(
                f"{label} = {shown(values.tolist())} is out of range: allowed (0, {upper:g}]"
            )
    if not (math.isfinite(duration_s) and 0 < duration_s <= 1e4):
        raise ValueError(f"duration_s = {shown(duration_s)} is out of range: allowed (0, 10000]")
    total_steps = round(duration_s / PLANT_DT_S)
    if total_steps % 100 or abs(total_steps * PLANT_DT_S - duration_s) > 1e-9:
        raise ValueError(
            f"duration_s = {shown(duration_s)} is out of range: allowed a multiple of 0.1 s"
        )
    if not (math.isfinite(window_s) and 0 < window_s <= duration_s):
        raise ValueError(
            f"window_s = {shown(window_s)} is out of range: allowed (0, duration_s = {duration_s:g}]"
        )
    if not (math.isfinite(noise_std_rad_s) and 0 <= noise_std_rad_s <= 10):
        raise ValueError(
            f"noise_std_rad_s = {shown(noise_std_rad_s)} is out of range: allowed [0, 10]"
        )

    chunk = _chunk_steps(total_steps)
    if policy is not None:  # one chunk per decision of the policy
        chunk = round(float(policy_kwargs.pop("control_dt_s", 0.1)) / PLANT_DT_S)
        if total_steps % chunk:
            raise ValueError(
                f"duration_s = {shown(duration_s)} is out of range: allowed a multiple of the "
                f"policy's decision period {chunk * PLANT_DT_S:g} s"
            )
    cells = [(float(w), float(v)) for w in wobs for v in speeds]
    n = len(cells)
    started = time.perf_counter()
    venv = gym.make_vec(
        env_id,
        num_envs=n,
        parameters=parameters,
        randomize=False,
        control_dt_s=chunk * PLANT_DT_S,
        episode_s=total_steps * PLANT_DT_S,
        noise_std_rad_s=float(noise_std_rad_s),
        **{**({"base_controller": controller} if policy is None else policy_kwargs), **extra},
    )
    observations = reset_each(
        venv,
        [seed + i for i in range(n)],
        [{"wob_n": w, "reference_speed_rad_s": v} for w, v in cells],
    )
    window_start = total_steps - round(window_s / PLANT_DT_S)
    stats = WindowStatistics(n)
    diverged = np.zeros(n, dtype=bool)
    actions = np.zeros((n, 1), dtype=np.float32)
    policy_state: Any = None
    n_chunks = total_steps // chunk
    bar = tqdm(
        total=n_chunks,
        desc=f"map {controller} ({n} cells)",
        unit="chunk",
        disable=not progress,
        leave=False,
    )
    with bar:
        for k in range(n_chunks):
            if policy is not None:
                actions, policy_state = policy.predict(
                    observations, policy_state, np.full(n, k == 0), deterministic=True
                )
            observations, _, terminated, _, _ = venv.step(actions)
            samples = venv.unwrapped.plant_samples()  # type: ignore[attr-defined]
            # a base controller's NaN or infinite torque at a step the string moved diverges
            # the cell (a compiled law's infinite torque is held at the limit, not ended)
            moved = np.isfinite(samples.states[..., 0])
            bad_torque = (moved & ~np.isfinite(samples.base_torque_nm)).any(axis=-1)
            diverged |= terminated | bad_torque
            bar.update()
            first = max(window_start - k * chunk, 0)
            if first >= chunk:
                continue
            stats.add(samples.bit_speed_rad_s[:, first:], samples.bit_stuck[:, first:])
    venv.close()
    severity = stats.severity()
    stuck_fraction = stats.stuck_fraction()
    severity[diverged] = np.nan
    stuck_fraction[diverged] = np.nan
    samples_in_window = stats.samples
    shape = (wobs.size, speeds.size)
    return StickSlipMap(
        controller=controller,
        wob_n=wobs,
        reference_speed_rad_s=speeds,
        severity=severity.reshape(shape),
        stuck_fraction=stuck_fraction.reshape(shape),
        duration_s=total_steps * PLANT_DT_S,
        window_s=samples_in_window * PLANT_DT_S,
        noise_std_rad_s=float(noise_std_rad_s),
        seed=int(seed),
        parameters=parameters,
        wall_time_s=time.perf_counter() - started,
        env_id=env_id,
        observation=observation if field else None,
        measured_depth_m=float(measured_depth_m) if measured_depth_m is not None else None,
        realism=level,
    )


_MAP_OWN_KEYWORDS: Final = frozenset(
    {"parameters", "randomize", "episode_s", "noise_std_rad_s", "measured_depth_m", "env_id"}
)
"""Env keywords that the map sets itself, whatever a policy was trained with."""


def _policy_env_kwargs(policy: MapPolicy, env_id: str) -> dict[str, Any]:
    """The env keywords of a policy's cells: its own (decision period, base controller,
    residual scale, observation mode, ...) without those the map sets; a policy trained on
    another env is refused."""
    kwargs = dict(policy.env_kwargs)
    trained_on = getattr(policy, "env_id", None) or kwargs.get("env_id", PAPER_ENV)
    if trained_on != env_id:
        raise ValueError(
            f"policy {shown(policy.name)} was trained on {trained_on}: map it with env_id {trained_on}"
            f", not {env_id}"
        )
    return {k: v for k, v in kwargs.items() if k not in _MAP_OWN_KEYWORDS}


def write_map_csv(result: StickSlipMap, path: str | Path) -> Path:
    """Write the map as CSV (``CSV_COLUMNS``, one row per cell, 6 significant digits)."""
    rows = [{k: f"{v:.6g}" for k, v in zip(CSV_COLUMNS, row, strict=True)} for row in result.rows()]
    return write_csv(rows, Path(path), CSV_COLUMNS)


# ---------------------------------------------------------------------------- command line
DESCRIPTION: Final = """\
Stick-slip map of each controller over weight on bit (WOB) x reference bit speed: each cell is
one run from rest, scored by its stick-slip severity and stuck time at the end of the run; CSV
and PNG per controller into --out (docs/reports/stick-slip-maps.md).

example: drill-gym map --controllers stiff_pi proposed --wob-n 5 --speed-n 4 --duration-s 40
"""


class _Defaults(NamedTuple):
    wob_min: float
    wob_max: float
    wob_n: int
    speed_min: float
    speed_max: float
    speed_n: int
    window: float
    parameters: str


DEFAULTS: Final[dict[str, _Defaults]] = {
    PAPER_ENV: _Defaults(40e3, 200e3, 20, 1.0, 16.0, 16, DEFAULT_WINDOW_S, "zribi2024"),
    FIELD_ENV: _Defaults(50e3, 200e3, 16, 40 * RPM, 160 * RPM, 13, FIELD_WINDOW_S, "field_2500m"),
}
"""The grid and run defaults of the command line on each env."""

DEFAULT_DURATION_S: Final = 100.0
"""Length of each run of the command line's maps, s."""


def _on_each(name: str, digits: int = 6) -> str:
    """The default of ``name`` on each env, as the help shows it."""
    paper, field_value = (getattr(DEFAULTS[e], name) for e in (PAPER_ENV, FIELD_ENV))
    if isinstance(paper, str):
        return f"{paper}; field: {field_value}"
    return f"{paper:.{digits}g}; field: {field_value:.{digits}g}"


_WOB: Final = {"low": 0.0, "high": MAX_WOB_N, "open_low": True, "unit": "N", "metavar": "N"}
_SPEED: Final = {"low": 0.0, "high": MAX_REFERENCE_RAD_S, "open_low": True, "unit": "rad/s"}
_COUNT: Final = {"low": 1, "high": 10_000}


@dataclass(frozen=True)
class MapSpec:
    """The settings of ``drill-gym map`` (its options are these fields); a grid setting left
    ``None`` takes the env's default (:data:`DEFAULTS`)."""

    controllers: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=controller_type,
            help=CONTROLLERS_OPTION_HELP,
            metavar="NAME",
            aliases=("--controller",),
            default_text="stiff_pi, none with --models",
        ),
    )
    # help: CONTROLLERS_OPTION_HELP (user classes are the same in every study)
    models: tuple[str, ...] = field(default=(), metadata=option(metavar="PATH"))
    """model folders to map too"""
    env_id: str = field(
        default=PAPER_ENV, metadata=option(choices=ENV_IDS, flag="--env", aliases=("--env-id",))
    )
    """the env of the cells"""
    depths: tuple[float, ...] = field(
        default=(),
        metadata=option(low=300.0, high=10_000.0, unit="m", metavar="M", default_text="preset's"),
    )
    """measured depths of the field string, m, one map each"""
    observations: tuple[str, ...] = field(
        default=OBSERVATIONS, metadata=option(choices=OBSERVATIONS)
    )
    """observation modes of the speed loops on the field string"""
    wob_min: float | None = field(
        default=None, metadata=option(**_WOB, default_text=_on_each("wob_min"))
    )
    """lowest WOB, N"""
    wob_max: float | None = field(
        default=None, metadata=option(**_WOB, default_text=_on_each("wob_max"))
    )
    """highest WOB, N"""
    wob_n: int | None = field(
        default=None, metadata=option(**_COUNT, default_text=_on_each("wob_n"))
    )
    """number of WOB values"""
    speed_min: float | None = field(
        default=None, metadata=option(**_SPEED, default_text=_on_each("speed_min", 3))
    )
    """lowest reference speed, rad/s"""
    speed_max: float | None = field(
        default=None, metadata=option(**_SPEED, default_text=_on_each("speed_max", 3))
    )
    """highest reference speed, rad/s"""
    speed_n: int | None = field(
        default=None, metadata=option(**_COUNT, default_text=_on_each("speed_n"))
    )
    """number of reference speeds"""
    duration_s: float = field(
        default=DEFAULT_DURATION_S,
        metadata=option(low=0.0, high=1e4, open_low=True, unit="s", aliases=("--duration",)),
    )
    """run length, s (a multiple of 0.1 s)"""
    window_s: float | None = field(
        default=None,
        metadata=option(
            low=0.0,
            high=1e4,
            open_low=True,
            unit="s",
            aliases=("--window",),
            default_text=_on_each("window"),
        ),
    )
    """analysed end of each run, s"""
    noise: float = field(default=0.0, metadata=option(low=0.0, high=10.0, unit="rad/s"))
    """speed measurement noise, rad/s"""
    parameters: str | None = field(
        default=None,
        metadata=option(
            choices=sorted(PRESETS) + sorted(DISTRIBUTED_PRESETS),
            default_text=_on_each("parameters"),
        ),
    )
    """plant parameter preset"""
    realism: str | None = field(
        default=None, metadata=option(choices=REALISM_LEVELS, metavar="LEVEL", default_text="env's")
    )
    """realism of sensors and top drive"""
    out: Path = field(default=Path("results"), metadata=option(parse=output_folder, metavar="DIR"))
    """output folder"""
    seed: int = field(default=0, metadata=option(low=0, high=BASE_SEED_HIGH))
    """reset seed of cell 0 (cell i: seed + i)"""
    no_plots: bool = False
    """write the CSV files only"""
    no_progress: bool = False
    """no progress bar"""

    def __post_init__(self) -> None:
        check_output_option(self.out)
        field_env = is_field(self.env_id)
        presets = DISTRIBUTED_PRESETS if field_env else PRESETS
        if self.preset not in presets:
            raise ValueError(
                f"argument --parameters: {self.preset} is not a preset of {self.env_id}: allowed "
                + ", ".join(sorted(presets))
            )
        if self.depths and not field_env:
            raise ValueError(f"argument --depths: is an option of the field string ({FIELD_ENV})")
        for depth in self.depths:
            bha = DISTRIBUTED_PRESETS[self.preset].bha_length_m
            if depth <= bha:
                raise ValueError(
                    f"argument --depths: {depth:g} is out of range: allowed > BHA length {bha} m"
                )
        try:  # the grid's own checks name the option
            self.wobs()
            self.speeds()
        except ValueError as err:
            raise ValueError(f"argument {err}") from None
        if abs(round(self.duration_s * 10) - self.duration_s * 10) > 1e-6:
            raise ValueError(
                f"argument --duration-s: {self.duration_s:g} is not a multiple of 0.1 s"
            )
        if self.window > self.duration_s:
            raise ValueError(
                f"argument --window-s: {self.window:g} is out of range: allowed (0, --duration-s = "
                f"{self.duration_s:g}] s"
            )

    def _grid(self, name: str) -> Any:
        value = getattr(self, name)
        return getattr(DEFAULTS[self.env_id], name) if value is None else value

    @property
    def preset(self) -> str:
        """The plant preset (default: the env's)."""
        return str(self._grid("parameters"))

    @property
    def window(self) -> float:
        """The analysis window, s (default: the env's)."""
        return float(self.window_s if self.window_s is not None else DEFAULTS[self.env_id].window)

    def wobs(self) -> np.ndarray:
        """The WOB of each grid row, N."""
        return grid_values(
            "wob", self._grid("wob_min"), self._grid("wob_max"), self._grid("wob_n"), MAX_WOB_N
        )

    def speeds(self) -> np.ndarray:
        """The reference bit speed of each grid column, rad/s."""
        return grid_values(
            "speed",
            self._grid("speed_min"),
            self._grid("speed_max"),
            self._grid("speed_n"),
            MAX_REFERENCE_RAD_S,
        )

    @property
    def controller_names(self) -> tuple[str, ...]:
        """The controllers, each once (default: ``stiff_pi``, none with models)."""
        return tuple(dict.fromkeys(self.controllers or (() if self.models else ("stiff_pi",))))

    @property
    def cells(self) -> int:
        """Cells of one map."""
        return int(self.wobs().size * self.speeds().size)

    def study(self, models: Sequence[MapPolicy] = (), task_cells: int = MAP_TASK_CELLS) -> MapStudy:
        """The study of these settings: the maps of the controllers and of ``models`` (the
        policies of :attr:`models`, loaded), ``task_cells`` cells per task."""
        depths: tuple[float, ...] = ()
        if is_field(self.env_id):
            string = DISTRIBUTED_PRESETS[self.preset]
            depths = tuple(dict.fromkeys(self.depths or (string.measured_depth_m,)))
        level = map_realism(self.env_id, self.realism)
        return MapStudy(
            self.controller_names,
            tuple(float(w) for w in self.wobs()),
            tuple(float(v) for v in self.speeds()),
            duration_s=self.duration_s,
            window_s=self.window,
            noise_std_rad_s=self.noise,
            seed=self.seed,
            parameters=self.parameters,
            task_cells=task_cells,
            env_id=self.env_id,
            observations=tuple(dict.fromkeys(self.observations)),
            depths_m=depths,
            # one entry per further compute_map option (none for the default map, so that
            # its settings hash, and the results written for it, stay as they were)
            keywords={} if level is None else {"realism": level},
            models=tuple(models),
        )


def _parser() -> ArgumentParser:
    parser = spec_parser("drill-gym map", DESCRIPTION, MapSpec, RunnerSpec)
    parser.usage = "drill-gym map [OPTIONS]"
    return parser


def _map_line(result: StickSlipMap, depth: float | None, written: Sequence[Path]) -> str:
    """The line printed for one map."""
    simulated = result.cells * result.duration_s
    return (
        f"{printable(result.label)}{'' if depth is None else f' at {depth:g} m'}: "
        f"{result.cells} cells "
        f"x {result.duration_s:g} s in {result.wall_time_s:.1f} s "
        f"({simulated / result.wall_time_s:,.0f} simulated s per wall s); "
        f"{int(result.unstable().sum())} cells in stick-slip; wrote "
        + " and ".join(str(p) for p in written)
    )


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym map``: compute, write and plot the maps; returns the exit code.

    Bad arguments end with one line on standard error naming the argument (exit code 2).
    """
    parser = _parser()
    args = parser.parse_args(argv)
    runner = spec_from_args(RunnerSpec, args)
    try:
        spec = spec_from_args(MapSpec, args)
    except ValueError as err:
        parser.error(str(err))
    level = map_realism(spec.env_id, spec.realism)
    refuse_on_ray(parser.fail, runner.backend().distributed, spec.controller_names)
    policies: list[MapPolicy] = []
    for folder in spec.models:
        try:
            loaded = load_policy(folder)
            _policy_env_kwargs(loaded, spec.env_id)
        except (OSError, ValueError) as err:
            parser.fail("--models", f"{folder}: {err}")
        policies.append(loaded)
    # a plain serial run: each map one task, the whole grid at once (one vector env, as fast
    # as it gets in one process); on Ray or into a database: MAP_TASK_CELLS
    task_cells = runner.task_size or (MAP_TASK_CELLS if runner.requested else spec.cells)
    try:
        study = spec.study(tuple(policies), task_cells)
    except ValueError as err:
        parser.error(str(err))
    outcome = runner.run(study, spec.out / "stick_slip_map.sqlite", progress=not spec.no_progress)
    results: dict[float | None, list[StickSlipMap]] = {}
    for result in study.maps(outcome):
        stem = result.file_stem()
        written = [write_map_csv(result, output_path(spec.out, stem, suffix=".csv"))]
        if not spec.no_plots:
            figure = map_figure(result)
            written.append(save_figure(figure, output_path(spec.out, stem, suffix=".png")))
        print(_map_line(result, result.measured_depth_m, written))
        results.setdefault(result.measured_depth_m, []).append(result)
    for depth, maps in results.items():
        if len(maps) > 1 and not spec.no_plots:
            name = "stick_slip_maps" + ("" if depth is None else f"_{depth:g}m")
            name += "" if level is None else f"_{level}"
            path = output_path(spec.out, name, suffix=".png")
            print(f"wrote {save_figure(maps_figure(maps), path)}")
    return 0


# ------------------------------------------------------------------- sweep adapter
MapRun: TypeAlias = tuple[str, str | None, float | None]
"""One map of a study: (controller, observation mode, measured depth in m); the last two are
``None`` on ``DrillString-v0``."""

_ARRAY_FIELDS: Final = ("wob_n", "reference_speed_rad_s", "severity", "stuck_fraction")
"""The fields of a :class:`StickSlipMap` that are its grid and its cells (not its settings)."""
_STUDY_KEYWORDS: Final = (
    "controller", "wob_n", "reference_speed_rad_s", "duration_s", "window_s", "noise_std_rad_s",
    "seed", "parameters", "progress", "env_id", "observation", "measured_depth_m",
)  # fmt: skip
"""The :func:`compute_map` arguments a :class:`MapStudy` sets itself (not in its ``keywords``)."""


def map_key(controller: str, observation: str | None = None, depth_m: float | None = None) -> str:
    """The item prefix of one map: ``stiff_pi`` on ``DrillString-v0``, ``stiff_pi/surface/
    1500.0m`` on the field string (the depth as its exact ``repr``)."""
    if observation is None or depth_m is None:
        return controller
    return f"{controller}/{observation}/{float(depth_m)!r}m"


def map_rows_task(
    controller: str | MapPolicy,
    rows: Sequence[int],
    wob_n: Sequence[float],
    reference_speed_rad_s: Sequence[float],
    duration_s: float,
    window_s: float,
    noise_std_rad_s: float,
    seed: int,
    parameters: str,
    env_id: str = PAPER_ENV,
    observation: str | None = None,
    measured_depth_m: float | None = None,
    keywords: Mapping[str, Any] | None = None,
) -> TaskResult:
    """The WOB rows ``rows`` (consecutive indices into the whole grid; ``wob_n`` their WOB
    values) of one map of ``controller`` (a registered name or a learned policy): one
    :func:`compute_map` over them (on ``env_id``, with ``observation``, ``measured_depth_m``
    and the further compute_map ``keywords``), cell ``i`` of the grid
    reset with ``seed + i``. Records ``{map_key}/row{r}``: ``severity`` and ``stuck_fraction``
    per reference speed (``None``: diverged) and ``map``, the map's settings as compute_map
    reports them (every field of :class:`StickSlipMap` but its arrays and wall time)."""
    first = int(rows[0])
    assert list(rows) == list(range(first, first + len(rows))), "rows must be consecutive"
    name = controller if isinstance(controller, str) else ""
    with user_controller_errors(name, " on the map"):  # a user's class: one line naming it
        result = compute_map(
            controller,
            list(wob_n),
            list(reference_speed_rad_s),
            duration_s=duration_s,
            window_s=window_s,
            noise_std_rad_s=noise_std_rad_s,
            seed=seed + first * len(reference_speed_rad_s),
            parameters=parameters,
            progress=False,
            env_id=env_id,
            observation=observation,
            measured_depth_m=measured_depth_m,
            **dict(keywords or {}),
        )
    settings = {
        f.name: getattr(result, f.name)
        for f in dataclasses.fields(result)
        if f.name not in (*_ARRAY_FIELDS, "wall_time_s")
    }
    settings["seed"] = int(seed)  # the map's cell 0, not this block's
    prefix = map_key(result.controller, result.observation, result.measured_depth_m)
    records = {
        f"{prefix}/row{r}": {
            "severity": result.severity[k].tolist(),
            "stuck_fraction": result.stuck_fraction[k].tolist(),
            "map": settings,
        }
        for k, r in enumerate(rows)
    }
    return TaskResult(records)


def _floats(values: Sequence[Any]) -> np.ndarray:
    """A record's list of numbers with ``None`` (a non-finite value in JSON) as NaN."""
    return np.array([math.nan if v is None else float(v) for v in values], dtype=np.float64)


@dataclass(frozen=True)
class MapStudy:
    """Stick-slip maps of ``controllers`` (and learned ``models``) over the same grid on the
    sweep runner.

    On ``DrillString-v0`` one map per controller; on ``DrillStringField-v0`` one per
    controller, measured depth and observation mode it can use (:meth:`runs`, the order of
    ``drill-gym map``). Each map equals the one :func:`compute_map` computes over the whole
    grid, in every field but its wall time.

    Attributes:
        controllers: Registered controller names.
        wob_n: WOB of each grid row, N.
        reference_speed_rad_s: Reference bit speed of each grid column, rad/s.
        duration_s, window_s, noise_std_rad_s, seed: As
            :func:`experiments.stick_slip_map.compute_map`.
        parameters: Plant preset of ``env_id`` (``None``: the env's default, ``zribi2024`` or
            ``field_2500m``).
        task_cells: Cells per task (rounded down to whole rows, at least one row); does not
            change the numbers.
        name: Name of the sweep.
        env_id: The env of the cells (:data:`experiments.field.ENV_IDS`).
        observations: On the field string, the observation modes to map each controller with
            (each with those it can use, :func:`experiments.field.observations_of`); not used
            on ``DrillString-v0``.
        depths_m: On the field string, the measured depths, m, one map each (empty: the
            preset's); none on ``DrillString-v0``.
        keywords: Further keywords of :func:`compute_map`, the same for every map (any it
            accepts but those the study sets itself); passed to every call and part of the
            spec.
        models: Learned policies (:class:`MapPolicy`) to map after the controllers, each with
            its own env keywords; a model's map is one task (the whole grid in one batch, as
            :func:`compute_map` runs it). Their fingerprints are part of the spec.
    """

    controllers: tuple[str, ...]
    wob_n: tuple[float, ...]
    reference_speed_rad_s: tuple[float, ...]
    duration_s: float = 100.0
    window_s: float = DEFAULT_WINDOW_S
    noise_std_rad_s: float = 0.0
    seed: int = 0
    parameters: str | None = None
    task_cells: int = MAP_TASK_CELLS
    name: str = "map"
    env_id: str = PAPER_ENV
    observations: tuple[str, ...] = OBSERVATIONS
    depths_m: tuple[float, ...] = ()
    keywords: Mapping[str, Any] = field(default_factory=dict)
    models: tuple[MapPolicy, ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        if self.controllers or not self.models:
            check_controllers(self.controllers)
        names = [m.name for m in self.models]
        if len(set(names)) != len(names) or set(names) & set(self.controllers):
            raise ValueError(f"models {shown(names)}: each model needs a name of its own")
        for model in self.models:
            _policy_env_kwargs(model, self.env_id)
        for label, values in (
            ("wob_n", self.wob_n),
            ("reference_speed_rad_s", self.reference_speed_rad_s),
        ):
            if not values:
                raise ValueError(f"{label} = [] is empty: the grid needs at least one value")
        check_task_size("task_cells", self.task_cells)
        steps = self.duration_s / 0.1
        if not (math.isfinite(steps) and 0 < steps <= 1e5 and abs(steps - round(steps)) < 1e-6):
            raise ValueError(
                f"duration_s = {shown(self.duration_s)} is out of range: allowed (0, 10000], a "
                "multiple of 0.1 s"
            )
        if not (math.isfinite(self.window_s) and 0 < self.window_s <= self.duration_s):
            raise ValueError(
                f"window_s = {shown(self.window_s)} is out of range: allowed (0, duration_s = "
                f"{self.duration_s:g}]"
            )
        presets = DISTRIBUTED_PRESETS if self.field else PRESETS
        if self.preset not in presets:
            raise ValueError(
                f"parameters = {shown(self.preset)} is not a preset of {self.env_id}: allowed "
                f"{', '.join(sorted(presets))}"
            )
        if self.field:
            check_observations(self.observations)
            for depth in self.depths_m:
                with_measured_depth(self.preset, depth)  # a depth the string cannot have
        elif self.depths_m:
            raise ValueError(
                f"depths_m = {shown(list(self.depths_m))}: measured depths are a setting of the field "
                f"string ({FIELD_ENV}), not of {self.env_id}"
            )
        accepted = set(inspect.signature(compute_map).parameters) - set(_STUDY_KEYWORDS)
        for key in self.keywords:
            if key not in accepted:
                raise ValueError(
                    f"keywords: {shown(key)} is not a further keyword of compute_map: allowed "
                    f"{', '.join(sorted(accepted)) or 'none'}"
                )

    @property
    def field(self) -> bool:
        """Whether the maps are of the field string (raises for an unknown env)."""
        return is_field(self.env_id)

    @property
    def preset(self) -> str:
        """The plant preset of the maps."""
        if self.parameters is not None:
            return self.parameters
        return str(DEFAULTS[self.env_id].parameters)

    def runs(self) -> list[MapRun]:
        """The maps, in the order of ``drill-gym map``: each controller, then (on the field
        string) each depth, then each observation mode the controller can use (with a level
        of realism in :attr:`keywords`, the level's observation for every controller); then
        each depth and each model (with the observation it was trained on)."""
        named: list[MapRun]
        if not self.field:
            named = [(c, None, None) for c in self.controllers]
            return list(dict.fromkeys([*named, *((m.name, None, None) for m in self.models)]))
        depths = self.depths_m or (DISTRIBUTED_PRESETS[self.preset].measured_depth_m,)
        level = map_realism(self.env_id, self.keywords.get("realism"))
        fixed = None if level is None else (str(realism_keywords(level)["observation"]),)
        named = [
            (c, o, float(d))
            for c in self.controllers
            for d in depths
            for o in (fixed or observations_of(c, self.observations))
        ]
        learned = [
            (m.name, fixed[0] if fixed else self._trained_observation(m), float(d))
            for d in depths
            for m in self.models
        ]
        return list(dict.fromkeys([*named, *learned]))

    @staticmethod
    def _trained_observation(model: MapPolicy) -> str:
        """The field env's observation mode ``model`` runs with in a map."""
        return str(dict(model.env_kwargs).get("observation") or "state")

    def spec(self) -> dict[str, Any]:
        """The map's settings (not the task size)."""
        return {
            "env_id": self.env_id,
            "maps": [list(run) for run in self.runs()],
            "wob_n": [float(w) for w in self.wob_n],
            "reference_speed_rad_s": [float(v) for v in self.reference_speed_rad_s],
            "duration_s": float(self.duration_s),
            "window_s": float(self.window_s),
            "noise_std_rad_s": float(self.noise_std_rad_s),
            "seed": int(self.seed),
            "parameters": self.preset,
            "keywords": dict(self.keywords),
            # only with models, so that the spec of a map of controllers stays as it was
            **({"models": [agent_fingerprint(m) for m in self.models]} if self.models else {}),
        }

    def items(self) -> list[str]:
        """One item per (map, WOB row)."""
        return [f"{map_key(*run)}/row{r}" for run in self.runs() for r in range(len(self.wob_n))]

    @functools.cached_property
    def _run_of_prefix(self) -> dict[str, MapRun]:
        return {map_key(*run): run for run in self.runs()}

    def record_schema(self, item: str) -> Schema:
        """A WOB row: the severity (>= 0) and the stuck fraction (in [0, 1]) at each reference
        speed (``None``: diverged), and the map's settings, which must be this study's."""
        controller, observation, depth = self._run_of_prefix[item.rpartition("/row")[0]]
        speeds = len(self.reference_speed_rad_s)
        settings = {
            "controller": controller,
            "noise_std_rad_s": float(self.noise_std_rad_s),
            "seed": int(self.seed),
            "parameters": self.preset,
            "env_id": self.env_id,
            "observation": observation,
            "measured_depth_m": depth,
            "realism": map_realism(self.env_id, self.keywords.get("realism")),
        }
        return Fields(
            {
                "severity": Values(Number(low=0.0), speeds),
                "stuck_fraction": Values(Number(low=0.0, high=1.0), speeds),
                "map": Fields(
                    {
                        **exactly(settings),  # the run's duration and window in whole steps
                        "duration_s": Near(float(self.duration_s)),
                        "window_s": Near(float(self.window_s)),
                    }
                ),
            }
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """Blocks of consecutive missing rows of one map, ``task_cells`` cells each (a
        model's: all of them)."""
        per_cells = max(1, self.task_cells // len(self.reference_speed_rad_s))
        models = {m.name: m for m in self.models}
        wanted = set(missing)
        tasks: list[Task] = []
        for controller, observation, depth in self.runs():
            model = models.get(controller)
            per_task = per_cells if model is None else len(self.wob_n)
            prefix = map_key(controller, observation, depth)
            rows = [r for r in range(len(self.wob_n)) if f"{prefix}/row{r}" in wanted]
            blocks: list[list[int]] = []
            for r in rows:  # consecutive runs, then blocks of per_task rows
                if blocks and blocks[-1][-1] == r - 1:
                    blocks[-1].append(r)
                else:
                    blocks.append([r])
            for run in blocks:
                for block in chunks(run, per_task):
                    tasks.append(
                        Task(
                            key=f"{prefix}/rows{block[0]}-{block[-1]}",
                            function=map_rows_task,
                            kwargs={
                                "controller": controller if model is None else model,
                                "rows": block,
                                "wob_n": [self.wob_n[r] for r in block],
                                "reference_speed_rad_s": list(self.reference_speed_rad_s),
                                "duration_s": self.duration_s,
                                "window_s": self.window_s,
                                "noise_std_rad_s": self.noise_std_rad_s,
                                "seed": self.seed,
                                "parameters": self.preset,
                                "env_id": self.env_id,
                                "observation": observation if model is None else None,
                                "measured_depth_m": depth,
                                "keywords": dict(self.keywords),
                            },
                            items=tuple(f"{prefix}/row{r}" for r in block),
                        )
                    )
        return tasks

    def maps(self, outcome: SweepOutcome) -> list[StickSlipMap]:
        """The maps, in the order of :meth:`runs`, from the sweep's records (their wall time:
        the sweep's)."""
        maps = []
        for run in self.runs():
            prefix = map_key(*run)
            records = [outcome.records[f"{prefix}/row{r}"] for r in range(len(self.wob_n))]
            maps.append(
                StickSlipMap(
                    wob_n=np.asarray(self.wob_n, dtype=np.float64),
                    reference_speed_rad_s=np.asarray(self.reference_speed_rad_s, dtype=np.float64),
                    severity=np.stack([_floats(r["severity"]) for r in records]),
                    stuck_fraction=np.stack([_floats(r["stuck_fraction"]) for r in records]),
                    wall_time_s=outcome.wall_time_s,
                    **records[0]["map"],
                )
            )
        return maps


# ------------------------------------------------------------------- stick-slip maps
SEVERITY_LABEL: Final = "stick-slip severity (max - min) / (2 mean)"
"""Colour-bar label of the severity: the bit speed's over the analysis window."""
STUCK_LABEL: Final = "stuck fraction of the window"
"""Colour-bar label of the stuck fraction."""
BOUNDARY_LABEL: Final = (
    f"boundary of stick-slip: the bit sticks, or severity > {STICK_SLIP_SEVERITY:g}"
)
"""Legend entry of the white line of the maps."""


def _heatmap(ax: Axes, result: StickSlipMap, quantity: str, title: str) -> Any:
    from matplotlib.colors import Normalize

    if quantity == "severity":
        data, norm, cmap = result.severity, Normalize(0.0, SEVERITY_LIMIT), "magma"
    else:
        data, norm, cmap = result.stuck_fraction, Normalize(0.0, 1.0), "viridis"
    mesh = ax.pcolormesh(
        cell_edges(result.reference_speed_rad_s),
        cell_edges(result.wob_n) / 1e3,
        np.ma.masked_invalid(data),
        cmap=cmap,
        norm=norm,
        shading="flat",
    )
    unstable = result.unstable()
    if unstable.any() and not unstable.all() and min(data.shape) > 1:
        ax.contour(
            result.reference_speed_rad_s,
            result.wob_n / 1e3,
            unstable.astype(float),
            levels=[0.5],
            colors="white",
            linewidths=1.6,
        )
    ax.set_title(title)
    ax.set_xlabel("reference bit speed (rad/s)")
    ax.set_ylabel("WOB (kN)")
    return mesh


def _boundary_legend(fig: Figure) -> None:
    from matplotlib.lines import Line2D

    handle = Line2D([], [], color="white", lw=2.0, label=BOUNDARY_LABEL)
    legend = fig.legend(handles=[handle], loc="outside lower center", fontsize=10, frameon=True)
    legend.get_frame().set_facecolor("0.45")
    for text in legend.get_texts():
        text.set_color("white")


def map_figure(result: StickSlipMap) -> Figure:
    """Severity and stuck-fraction heatmaps of one map, side by side, with labelled colour bars
    and the stick-slip boundary explained."""
    fig = new_figure(11.0, 4.9)
    axes = fig.subplots(1, 2)
    for ax, quantity, label in (
        (axes[0], "severity", f"severity, capped at {SEVERITY_LIMIT:g}"),
        (axes[1], "stuck", "stuck fraction"),
    ):
        mesh = _heatmap(ax, result, quantity, f"{result.label}: {label}")
        fig.colorbar(
            mesh,
            ax=ax,
            extend="max" if quantity == "severity" else "neither",
            label=SEVERITY_LABEL if quantity == "severity" else STUCK_LABEL,
        )
    fig.suptitle(_caption(result))
    _boundary_legend(fig)
    return fig


def maps_figure(results: Sequence[StickSlipMap]) -> Figure:
    """All maps side by side: one column per controller, severity above stuck fraction.

    Raises:
        ValueError: if ``results`` is empty.
    """
    if not results:
        raise ValueError("maps_figure needs at least one map")
    n = len(results)
    fig = new_figure(3.1 * n + 1.9, 7.0)
    axes = np.asarray(fig.subplots(2, n, squeeze=False, sharex=True, sharey=True))
    severity: list[Any] = []
    stuck: list[Any] = []
    for col, result in enumerate(results):
        severity.append(_heatmap(axes[0, col], result, "severity", result.label))
        stuck.append(_heatmap(axes[1, col], result, "stuck", result.label))
        if col:
            axes[0, col].set_ylabel("")
            axes[1, col].set_ylabel("")
        axes[0, col].set_xlabel("")
    fig.colorbar(severity[-1], ax=list(axes[0]), extend="max", label=SEVERITY_LABEL)
    fig.colorbar(stuck[-1], ax=list(axes[1]), label=STUCK_LABEL)
    fig.suptitle(
        f"stick-slip severity (top, colours capped at {SEVERITY_LIMIT:g}) and stuck fraction "
        f"(bottom)\n{_caption(results[0])}"
    )
    _boundary_legend(fig)
    return fig


def _caption(result: StickSlipMap) -> str:
    noise = "no noise" if result.noise_std_rad_s == 0 else f"noise {result.noise_std_rad_s:g} rad/s"
    plant = f"plant {result.parameters}"
    if result.measured_depth_m is not None:
        plant += f" at {result.measured_depth_m:,.0f} m"
    return (
        f"{plant}, runs of {result.duration_s:g} s from rest, last "
        f"{result.window_s:g} s analysed, {noise}"
    )


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
