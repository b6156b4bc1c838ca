"""``DrillString-v0``: the Gymnasium contract around the drill-string plant and nothing else."""

from __future__ import annotations

import copy
import dataclasses
import types
from typing import Any, ClassVar, Final, NamedTuple, NoReturn, SupportsFloat

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium.envs.registration import EnvSpec

from drill_env import render
from drill_env.batch import StringBatch
from drill_env.distributed import Chain, discretize
from drill_env.evaluation import PlantSamples
from drill_env.layout import (
    OBS_BOUND,
    REP_BASE_TORQUE,
    REP_BIT_SPEED,
    REP_BIT_STUCK,
    REP_COMMAND,
    REP_LAW_ERROR,
    REP_LAW_GAIN,
    REP_REFERENCE,
    REP_STATUS,
    REP_SURFACE_TORQUE,
    REP_TELEMETRY_AGE,
    REP_TELEMETRY_BIT_SPEED,
    REP_TELEMETRY_RECEIVED,
    REP_TIME,
    REP_TOP_DRIVE_SPEED,
    REP_TORQUE,
    REP_WOB,
    STATUS_OK,
)
from drill_env.options import EnvConfig, FieldEnvConfig
from drill_env.rewards import DIVERGED_REWARD, TERMS, report_reward
from drill_env.validation import shown

__all__ = [
    "DrillStringEnv",
    "DrillStringFieldEnv",
    "EpisodeStepsSpec",
    "StringState",
    "copy_batch_env",
    "copy_env_attributes",
    "refuse_pickling",
    "report_info",
    "validate_actions",
]


def report_info(report: Any, residual: bool, telemetry: bool) -> dict[str, Any]:
    """The physical ``info`` values (units in the keys) of one report row (a list of floats,
    for one env) or of an array of rows (a vector env; the columns are copied).

    Keys: ``time_s``, ``bit_speed_rad_s``, ``top_drive_speed_rad_s``, ``reference_speed_rad_s``,
    ``top_drive_torque_nm`` (applied, after the actuator), ``torque_command_nm`` (before it),
    ``surface_torque_nm`` (the measured torque at the top of the string), ``wob_n``,
    ``bit_stuck``; in residual mode also ``base_torque_nm``, ``sliding_variable_rad_s`` (the
    base controller's error signal) and ``adaptive_gain``; with telemetry also
    ``telemetry_bit_speed_rad_s``, ``telemetry_age_s`` and ``telemetry_received`` (before the
    first value arrives: 0 rad/s, the time since the start, and False).
    """
    if isinstance(report, np.ndarray):
        r = report
        info: dict[str, Any] = {key: r[:, index].copy() for key, index in _INFO_COLUMNS}
        info["bit_stuck"] = r[:, REP_BIT_STUCK] > 0.5
        columns = [
            *(_RESIDUAL_COLUMNS if residual else ()),
            *(_TELEMETRY_COLUMNS if telemetry else ()),
        ]
        info.update({key: r[:, index].copy() for key, index in columns})
        return info
    info = {key: report[index] for key, index in _INFO_COLUMNS}
    info["bit_stuck"] = report[REP_BIT_STUCK] > 0.5
    if residual:
        for key, index in _RESIDUAL_COLUMNS:
            info[key] = report[index]
    if telemetry:
        for key, index in _TELEMETRY_COLUMNS:
            info[key] = report[index]
        info["telemetry_received"] = report[REP_TELEMETRY_RECEIVED] > 0.5
    return info


def refuse_pickling(env: object) -> NoReturn:
    """``TypeError``: an env cannot be pickled or shallow-copied (its compiled kernel runs on
    the addresses of its own arrays and its compiled base controller); say what to do instead."""
    name = type(env).__name__
    raise TypeError(
        f"{name} cannot be pickled or shallow-copied: its compiled kernel holds the addresses "
        "of its own memory. Use copy.deepcopy(env) for an independent copy in the same state, "
        "or make a new env with gymnasium.make(...) (in another process: pass the id and "
        "keywords, not the env)"
    )


def copy_batch_env(env: Any, memo: dict[int, Any]) -> Any:
    """A deep copy of ``env`` (a single or vector env whose engine is a
    :class:`drill_env.batch.StringBatch` at ``env._batch``) that runs on its own memory.

    ``copy.deepcopy`` alone is not enough: the kernel takes its arrays by address
    (:class:`drill_env.kernel.PackedArrays`, which copies itself with the copies' addresses),
    a deep copy of a numpy view is an array of its own (the rows and noise blocks the env and
    its batch keep as views would no longer reach the kernel's arrays), and a closure is not
    copied at all (the coupled loop's holds its arrays). Here every view held by the env, its
    batch and its episodes becomes the same view of the copied arrays, and every closure of
    theirs is rebuilt on the copies of what it holds. The rendering history is copied; the
    copy draws its own frames (and opens its own window in ``human`` mode).

    Raises:
        TypeError: when the copy would still share memory with ``env`` (then make a new env
            with ``gymnasium.make``).
    """
    cls = type(env)
    twin = copy_env_attributes(env, memo)
    batch, twin_batch = env._batch, twin._batch
    originals = [*batch.arrays, *(batch.coupled_arrays or ())]
    copies = [*twin_batch.arrays, *(twin_batch.coupled_arrays or ())]
    pairs = [(env, twin), (batch, twin_batch)]
    pairs += [
        (e, t) for e, t in zip(batch.episodes, twin_batch.episodes, strict=True) if e is not None
    ]
    for original, copied in pairs:
        for key, value in vars(original).items():
            if isinstance(value, np.ndarray) and value.base is not None:
                view = _same_view(value, originals, copies)
                if view is not None:
                    vars(copied)[key] = view
            elif isinstance(value, types.FunctionType) and value.__closure__:
                vars(copied)[key] = _rebound_closure(value, memo)
    for _, copied in pairs:
        for key, value in vars(copied).items():
            if isinstance(value, np.ndarray) and any(
                np.may_share_memory(value, array) for array in originals
            ):
                raise TypeError(
                    f"{cls.__name__} cannot be deep-copied: {key} of the copy would share the "
                    "original's memory; make a new env with gymnasium.make(...)"
                )
    return twin


def copy_env_attributes(env: Any, memo: dict[int, Any]) -> Any:
    """A new object of ``env``'s class whose attributes are deep copies of ``env``'s (through
    ``memo``); the rendering's history is copied, its frames drawn afresh."""
    twin = object.__new__(type(env))
    memo[id(env)] = twin
    for key, value in vars(env).items():
        if key == "_rendering":
            vars(twin)[key] = _copied_rendering(value, memo)
        else:
            vars(twin)[key] = copy.deepcopy(value, memo)
    return twin


def _same_view(
    view: npt.NDArray[Any], originals: list[npt.NDArray[Any]], copies: list[npt.NDArray[Any]]
) -> npt.NDArray[Any] | None:
    """The view of the copy that ``view`` is of the original array it lies in (same offset,
    shape and strides), or None when it lies in none of ``originals``."""
    start = view.__array_interface__["data"][0]
    for original, twin in zip(originals, copies, strict=True):
        low = original.__array_interface__["data"][0]
        if original.nbytes and low <= start < low + original.nbytes:
            return np.ndarray(
                view.shape, view.dtype, buffer=twin, offset=start - low, strides=view.strides
            )
    return None


def _rebound_closure(function: types.FunctionType, memo: dict[int, Any]) -> types.FunctionType:
    """``function`` with each value it closes over replaced by that value's copy in ``memo``
    (as is when it was not copied: constants, compiled code)."""
    cells = tuple(
        types.CellType(memo.get(id(cell.cell_contents), cell.cell_contents))
        for cell in function.__closure__ or ()
    )
    rebound = types.FunctionType(
        function.__code__, function.__globals__, function.__name__, function.__defaults__, cells
    )
    rebound.__kwdefaults__ = function.__kwdefaults__
    return rebound


def _copied_rendering(
    rendering: render.EnvRendering | None, memo: dict[int, Any]
) -> render.EnvRendering | None:
    """A rendering with a copy of ``rendering``'s history that draws its own frames."""
    if rendering is None:
        return None
    twin = copy.copy(rendering)
    twin.history = copy.deepcopy(rendering.history, memo)
    twin._renderer = None
    if rendering.window is not None:
        twin.window = render.HumanWindow(rendering.window.fps, rendering.window.title)
    return twin


_INFO_COLUMNS: Final = (
    ("time_s", REP_TIME),
    ("bit_speed_rad_s", REP_BIT_SPEED),
    ("top_drive_speed_rad_s", REP_TOP_DRIVE_SPEED),
    ("reference_speed_rad_s", REP_REFERENCE),
    ("top_drive_torque_nm", REP_TORQUE),
    ("torque_command_nm", REP_COMMAND),
    ("surface_torque_nm", REP_SURFACE_TORQUE),
    ("wob_n", REP_WOB),
)
_RESIDUAL_COLUMNS: Final = (
    ("base_torque_nm", REP_BASE_TORQUE),
    ("sliding_variable_rad_s", REP_LAW_ERROR),
    ("adaptive_gain", REP_LAW_GAIN),
)
_TELEMETRY_COLUMNS: Final = (
    ("telemetry_bit_speed_rad_s", REP_TELEMETRY_BIT_SPEED),
    ("telemetry_age_s", REP_TELEMETRY_AGE),
)


def validate_actions(
    action: Any, num: int, batched: bool = False, size: int = 1
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Check ``action`` (``num`` strings' ``size`` values each, in [-1, 1]) and clip it;
    returns (clipped, was_clipped), shaped ``(num,)`` for one value per string, else
    ``(num, size)``.

    A single env takes shape ``(size,)`` (or a scalar when ``size`` is 1); a vector env
    (``batched``) takes ``(num, size)`` (or ``(num,)`` when ``size`` is 1). Real numbers only:
    integers and floats (Python or numpy); bools, complex numbers, strings, objects and masked
    arrays are refused.

    Raises:
        ValueError: naming ``action`` when it is not real, not finite or not of the right shape.
    """
    if (
        not batched
        and size == 1
        and type(action) is np.ndarray
        and action.shape == (1,)
        and action.dtype.kind == "f"
    ):  # the common case
        v = float(action[0])
        if -1.0 <= v <= 1.0:
            return np.array([v]), np.zeros(1, dtype=bool)
    elif (
        batched
        and type(action) is np.ndarray
        and action.dtype.kind == "f"
        and action.dtype.itemsize <= 8
        and action.shape in ((num, size), (num,) if size == 1 else (num, size))
    ):  # the common batched case: real values all in [-1, 1] (NaN fails the test)
        a = action.astype(np.float64).reshape((num,) if size == 1 else (num, size))
        if np.abs(a).max() <= 1.0:
            return a, np.zeros(a.shape, dtype=bool)
    expected = f"({size},)" if not batched else f"({num}, {size})"
    if type(action) is np.ndarray:  # a plain array (a masked array is a subclass)
        a = action
    elif isinstance(action, np.ma.MaskedArray):
        raise ValueError(
            f"action must be a plain array of real numbers with shape {expected}, got a masked "
            "array (fill it first: action.filled())"
        )
    else:
        try:
            a = np.asarray(action)
        except (TypeError, ValueError, OverflowError):
            a = np.asarray(None)
    if a.dtype.kind not in "fiu":
        raise ValueError(
            f"action must be numeric (real numbers) with shape {expected}, got {shown(action)} "
            f"(dtype {a.dtype})"
        )
    allowed = ((size,), ()) if not batched else ((num, size), (num,))
    if a.shape not in allowed[: 2 if size == 1 else 1]:
        raise ValueError(f"action must have shape {expected}, got shape {a.shape}")
    if a.dtype.itemsize > 8:  # long double: beyond float64 it becomes inf, refused below
        with np.errstate(over="ignore"):
            a = a.astype(np.float64)
    a = np.asarray(a, dtype=np.float64).reshape((num,) if size == 1 else (num, size))
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {shown(action)}")
    clipped = (a < -1.0) | (a > 1.0)
    return np.clip(a, -1.0, 1.0), clipped


class StringState(NamedTuple):
    """The true state of a distributed string at one instant (``DrillStringFieldEnv.
    string_state()``), ``n`` nodes from the top drive (node 0) down to the bit (node ``n - 1``).

    Attributes:
        node_depth_m: Depth of each node along the hole, (n,), m.
        speed_rad_s: Speed of each node, (n,), rad/s.
        twist_rad: Twist ``phi_e - phi_{e+1}`` of each element, (n - 1,), rad.
        torque_nm: Torque each element carries, ``k_e theta_e + c_e (w_e - w_{e+1})``,
            (n - 1,), N m; element 0's is the torque at the top of the string (the surface
            torque, before any sensor).
    """

    node_depth_m: npt.NDArray[np.float64]
    speed_rad_s: npt.NDArray[np.float64]
    twist_rad: npt.NDArray[np.float64]
    torque_nm: npt.NDArray[np.float64]


class EpisodeStepsSpec:
    """Mixin of an env that truncates its own episodes after ``_episode_steps`` decisions: its
    ``spec`` (set by ``gymnasium.make``) carries that count as ``max_episode_steps``."""

    _spec: EnvSpec | None = None

    @property
    def _episode_steps(self) -> int:
        raise NotImplementedError

    @property
    def spec(self) -> EnvSpec | None:
        """The registration spec, with ``max_episode_steps`` the decisions that ``episode_s``
        and ``control_dt_s`` make (the env truncates itself there)."""
        return self._spec

    @spec.setter
    def spec(self, value: EnvSpec | None) -> None:
        if value is not None and value.max_episode_steps is None:
            value = dataclasses.replace(value, max_episode_steps=self._episode_steps)
        self._spec = value


class DrillStringEnv(EpisodeStepsSpec, gym.Env[npt.NDArray[np.float32], npt.NDArray[np.float32]]):
    """Torsional stick-slip control of a 4-DOF drill string.

    ## Description
    A top drive turns a drill string of pipes, collars (BHA) and a bit; the bit rubs on rock
    with Karnopp friction, which drops from the static ``T_a = mu_a WOB R`` to the sliding
    ``T_0 = mu_0 WOB R``. The agent sets the top-drive torque so that the bit turns at the
    reference speed without sticking. The plant is docs/specification.md section 1 (Zribi,
    Sidhom & Gharib 2024, eq. 27-29), integrated at 1 ms with event-located stick and
    break-away; the torque is held over each ``control_dt_s`` decision period.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``; out-of-range values are clipped and counted in ``info``, and
    a NaN, infinite or wrongly shaped action raises ``ValueError``.

    | mode | top-drive torque ``u`` (N m) | action 0 means |
    |---|---|---|
    | direct (``base_controller=None``) | ``min_torque + (a + 1) / 2 (max_torque - min_torque)`` | the middle of the torque range, 25 kN m by default: about twice the steady drilling torque of the default scenario (13.0 kN m, ``a = -0.48``), so the bit overspins |
    | residual | ``clip(u_base + residual_scale_nm a, min_torque, max_torque)`` | the base controller alone (``drill_env.evaluation.ZeroAction``) |

    In residual mode the base controller computes ``u_base`` at every 1 ms plant step.

    ## Observation Space
    ``Box(-50, 50, (9,), float32)``, or ``(11,)`` in residual mode; each entry is a physical
    value divided by its scale (``drill_env.layout.observation_fields``) and clipped to +-50.

    | index | observation | scale |
    |---|---|---|
    | 0, 2, 4, 6 | measured speeds of top drive, pipes, collars, bit (noisy) | 20 rad/s |
    | 1, 3, 5 | twists top drive-pipes, pipes-collars, collars-bit (exact) | 20 rad |
    | 7 | reference bit speed | 20 rad/s |
    | 8 | last applied top-drive torque | max(abs(min_torque), abs(max_torque)) |
    | 9 | base controller torque (residual mode) | same as 8 |
    | 10 | base controller sliding variable s (residual mode) | 20 rad/s |

    ## Rewards
    Per decision period, with ``e = V_ref - w_bit`` (true bit speed) at every plant step:

    ``r = -(w_t T + w_c C + w_s S) / (w_t + w_c + w_s) - w_q Q - w_r R``, in ``[-2, 0]`` with
    the default weights ``RewardWeights(tracking=1, chattering=0.1, stuck=0,
    chattering_scale_nm=50_000, torque=1, residual=0)``: the shipped agent's training recipe
    (``drill_env.rewards``). Each term is in ``[0, 1]``; ``info["reward_terms"]`` gives them
    all, weighted or not. A diverged step gets -1.

    | term | definition | typical range (5th-95th percentile) |
    |---|---|---|
    | ``T`` tracking | ``mean(min(abs(e) / max(V_ref, 1 rad/s), 1))`` (1: the bit stuck) | 0.02-1 |
    | ``C`` chattering | ``min(TV(u) / 50 kN m, 1)``, TV the total variation of the applied torque over the period | 0.3-0.4 for ``proposed`` with the 0.1 rad/s noise, 0-0.8 for random direct actions |
    | ``S`` stuck | share of the plant steps with the bit stuck (weight 0 by default: ``T`` already counts a stuck bit as a full error) | 0-1 |
    | ``Q`` torque | ``mean(u^2) / max(abs(min_torque), abs(max_torque))^2`` (the paper's RMSD, an energy penalty) | 0.04-0.4 |
    | ``R`` residual | ``mean((u - u_base)^2) / residual_scale^2``, ``u_base`` clipped to the torque range (residual mode) | 0-0.9 for random residuals (it can exceed 1 behind the field top drive's lag) |

    The typical ranges are printed by ``benchmarks/reward_terms.py`` (default keywords,
    randomised episodes).

    ## Starting State
    At rest, ``x = 0``, bit stuck. The scenario (WOB profile, reference, uncertainty) is drawn
    from ``randomization`` at every reset when ``randomize=True`` (WOB U(60, 200) kN with a 50 %
    chance of one step change at mid-episode, V_ref U(4, 16) rad/s, Delta1..3 U(0, 0.75) on the
    plant), else taken from the keywords. Every draw comes from generators spawned from the
    reset seed, one per component (``wob``, ``reference``, ``uncertainty``, ``noise``).

    ## Episode End
    Truncation after ``episode_s`` (the env truncates itself; no step limit is registered, and
    ``env.spec.max_episode_steps`` is ``episode_s / control_dt_s``, 1000 by default). An explicit
    ``gym.make(..., max_episode_steps=n)`` adds Gymnasium's ``TimeLimit``, which may end an
    episode earlier. Termination when the state is not finite or leaves the physical bounds
    (1000 rad/s, 1000 rad, ``drill_env.limits``): ``info["termination_reason"] = "diverged"``,
    the observation stays finite. A Python ``base_controller`` that returns a NaN or infinite
    torque ends the episode the same way, with ``termination_reason`` naming it
    (``"base_controller Name returned nan N m"``); one that returns anything but a real number
    raises ``TypeError`` naming it.

    ## Arguments
    | keyword | meaning | default |
    |---|---|---|
    | ``parameters`` | preset name (``zribi2024``, ``navarro_lopez2007``) or parameters | ``zribi2024`` |
    | ``randomize`` | draw the scenario at each reset | ``True`` |
    | ``wob_n`` | weight on bit, N (``randomize=False``) | 97,347 |
    | ``wob_step_time_s``, ``wob_final_n`` | one WOB step change (new rock layer) | none |
    | ``reference_speed_rad_s`` | rad/s, or a ``SpeedProfile`` (steps, ramp) | 12 |
    | ``uncertainty`` | ``nominal``, ``condition1..3`` or ``(D1, D2, D3)`` | ``nominal`` |
    | ``uncertainty_reading`` | ``plant`` or ``controller`` | ``plant`` |
    | ``noise_std_rad_s`` | measurement noise on the speeds, rad/s | 0.1 |
    | ``episode_s`` | episode length, s | 100 |
    | ``control_dt_s`` | decision period, multiple of 1 ms (``episode_s`` a multiple of it) | 0.1 |
    | ``base_controller`` | ``None``, a registered name or a controller object | ``None`` |
    | ``residual_scale_nm`` | residual torque per unit action, N m | 20,000 |
    | ``min_torque_nm``, ``max_torque_nm`` | torque limits, N m | 0, 50,000 |
    | ``randomization`` | ``Randomization`` ranges | see Starting State |
    | ``reward_weights`` | ``RewardWeights`` | see Rewards |
    | ``render_mode`` | ``None``, ``"rgb_array"`` or ``"human"`` (see Rendering) | ``None`` |

    ``reset(options=...)`` takes the scenario keywords (``drill_env.options.PER_EPISODE_KEYWORDS``)
    for one episode; unknown keys are errors that list the valid ones.

    ## Info
    ``time_s``, ``bit_speed_rad_s``, ``top_drive_speed_rad_s``, ``reference_speed_rad_s``,
    ``top_drive_torque_nm``, ``wob_n``, ``bit_stuck``, ``reward_terms``, ``action_clipped``,
    ``actions_clipped_total``; in residual mode also ``base_torque_nm``, ``residual_torque_nm``,
    ``sliding_variable_rad_s``, ``adaptive_gain``; ``termination_reason`` when terminated; the
    state slots a compiled base controller names (``drill_env.control.CompiledLaw``
    ``info_slots`` and ``estimate_slots``: with ``observation="surface"`` the sliding-mode
    controllers' observer reports ``estimated_<state>`` and ``estimate_error_<state>`` for the
    seven entries of the 4-DOF state, and ``estimated_bit_torque_nm``; docs/observer.md).

    ## Rendering
    ``render_mode="rgb_array"``: ``render()`` returns a ``(480, 800, 3)`` uint8 frame of the
    last 20 s (:mod:`drill_env.render`): the four elements as dials turning at their absolute
    angles, the twists between them, the bit marked STUCK (red) or SLIPPING (green), traces
    of bit, top-drive and reference speed, top-drive torque and the twists along the string,
    the time and the WOB. ``render_mode="human"`` shows the same frames in a matplotlib window
    after every reset and step, at most ``render_fps`` a second, and needs a display (else a
    ``RuntimeError`` that says so). ``metadata["render_fps"]`` is ``1 / control_dt_s``, one
    frame per decision, so a video (``gymnasium.wrappers.RecordVideo``) plays in real time;
    an instance lists ``"human"`` in its ``metadata["render_modes"]`` only where a display
    exists. Without a render mode the env keeps no history and imports no matplotlib.

    ## Version History
    * v0: initial version.

    ## Example
    >>> import gymnasium as gym, drill_env
    >>> env = gym.make("DrillString-v0", randomize=False, noise_std_rad_s=0.0)
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    """

    metadata: dict[str, Any] = {
        "render_modes": list(render.RENDER_MODES),
        "render_fps": 10,  # one frame per decision at the default control_dt_s = 0.1 s
    }

    config_type: ClassVar[type[EnvConfig]] = EnvConfig
    """The keywords this env takes."""

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        render.check_render_mode(render_mode)  # first: a bad value is refused before any work
        self._spec: EnvSpec | None = None
        self.config = self.config_type.from_kwargs(kwargs)
        self._batch = StringBatch(self.config, 1)
        size = self._batch.obs_size
        self.observation_space = gym.spaces.Box(-OBS_BOUND, OBS_BOUND, (size,), np.float32)
        self._residual_scale = self.config.residual_scale_nm if self.config.residual else None
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self._started = False
        self._running = False  # started, and the episode has not ended by diverging
        # The hot path's constants: the reward of a report row, the info columns, the rows.
        self._reward = report_reward(
            self.config.reward_weights, self.config.torque_scale_nm, self._residual_scale
        )
        b = self._batch
        self._extra_columns = (*(_RESIDUAL_COLUMNS if b.residual else ()),) + (
            *(_TELEMETRY_COLUMNS if self.config.telemetry else ()),
        )
        self._telemetry = self.config.telemetry
        self._more_info = b.reports_law_slots or b.coupled
        self._report_row = b.report[0]
        self._obs_row = b.obs[0]
        # Rendering (drill_env.render): nothing is kept or drawn unless a render_mode is set.
        self.render_mode = render_mode
        self.metadata = {
            **type(self).metadata,
            "render_modes": render.available_render_modes(),
            "render_fps": 1.0 / self.config.control_dt_s,
        }
        self._rendering = (
            None
            if render_mode is None
            else render.EnvRendering(
                render_mode, (self._batch.x.shape[1] + 1) // 2, self.config.control_dt_s
            )
        )

    @property
    def _episode_steps(self) -> int:
        return self.config.max_steps

    @property
    def batch(self) -> StringBatch:
        """The engine (a batch of one)."""
        return self._batch

    @property
    def observation_names(self) -> tuple[str, ...]:
        """The name of each observation entry, in order (``drill_env.layout.observation_fields``)."""
        return tuple(f.name for f in self._batch.fields)

    def plant_samples(self) -> PlantSamples:
        """The last step's samples at every plant step (views, valid until the next step)."""
        return PlantSamples.from_records(self._batch.records[0])

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        if isinstance(seed, np.integer):  # Gymnasium takes a Python int only
            seed = int(seed)
        super().reset(seed=seed)
        root = None
        if seed is None and not self._started:
            # Without any seed, derive the first episode from Gymnasium's own generator.
            root = np.random.SeedSequence(int(self.np_random.integers(2**63)))
        self._batch.reset_string(0, seed, options, previous_root=root)
        self._started = True
        self._running = True
        obs = self._obs_row.copy()
        report = self._report_row.tolist()
        if self._rendering is not None:
            self._record(report, new_episode=True)
        return obs, self._info(dict.fromkeys(TERMS, 0.0), report, 0.0)

    def step(
        self, action: Any
    ) -> tuple[npt.NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        if not self._running:
            if not self._started:
                raise RuntimeError("call reset() before step()")
            raise RuntimeError("the episode has ended (diverged): call reset()")
        common = type(action) is np.ndarray and action.shape == (1,) and action.dtype.kind == "f"
        value = float(action[0]) if common else 2.0
        was_clipped = False
        if not -1.0 <= value <= 1.0:  # anything but a float array in range (or NaN): checked
            a, clipped = validate_actions(action, 1)
            value, was_clipped = float(a[0]), bool(clipped[0])
        b = self._batch
        episode = b.episodes[0]
        assert episode is not None
        if was_clipped:
            episode.actions_clipped += 1
        command = b.step_one(value)
        report = self._report_row.tolist()
        terms, reward = self._reward(report)
        terminated = report[REP_STATUS] != STATUS_OK
        truncated = not terminated and report[REP_TIME] >= episode.duration_s
        info = self._info(terms, report, command)
        if was_clipped:
            info["action_clipped"] = True
        if terminated:
            reward = DIVERGED_REWARD
            self._running = False
            info["termination_reason"] = b.end_reason(0)
        if self._rendering is not None:
            self._record(report)
        return self._obs_row.copy(), reward, terminated, truncated, info

    # ------------------------------------------------------------------ copies
    def __deepcopy__(self, memo: dict[int, Any]) -> DrillStringEnv:
        """An independent env in the same state (:func:`copy_batch_env`): given the same
        actions it continues bit for bit as this one would, on its own memory."""
        return copy_batch_env(self, memo)

    def __reduce_ex__(self, protocol: Any) -> NoReturn:
        refuse_pickling(self)

    # ------------------------------------------------------------------ rendering
    def _record(self, report: list[float], new_episode: bool = False) -> None:
        """Append the state now to the render history (only with a ``render_mode``)."""
        assert self._rendering is not None
        self._rendering.record(
            report[REP_TIME],
            self._batch.x[0],
            report[REP_TORQUE],
            report[REP_REFERENCE],
            report[REP_WOB],
            report[REP_BIT_STUCK] > 0.5,
            new_episode=new_episode,
        )

    def render(self) -> npt.NDArray[np.uint8] | None:
        """The frame of the last ``WINDOW_S`` s, ``(480, 800, 3)`` uint8, in ``rgb_array``
        mode; ``None`` in ``human`` mode (the window shows every reset and step) and without a
        ``render_mode`` (a warning, as Gymnasium's envs do)."""
        if self._rendering is None:
            gym.logger.warn(
                "render() called without a render_mode: pass render_mode='rgb_array' or "
                "'human' to gym.make"
            )
            return None
        if not self._started:
            raise RuntimeError("call reset() before render()")
        return self._rendering.render()

    def close(self) -> None:
        if self._rendering is not None:
            self._rendering.close()

    def _info(self, terms: dict[str, float], report: list[float], command: float) -> dict[str, Any]:
        """The info dict of one report row (:func:`report_info`'s values, in its order) with
        the reward ``terms`` and the step's ``command`` (the residual in residual mode), N m."""
        info: dict[str, Any] = {key: report[index] for key, index in _INFO_COLUMNS}
        info["bit_stuck"] = report[REP_BIT_STUCK] > 0.5
        for key, index in self._extra_columns:
            info[key] = report[index]
        if self._telemetry:
            info["telemetry_received"] = report[REP_TELEMETRY_RECEIVED] > 0.5
        info["reward_terms"] = terms
        info["action_clipped"] = False
        info["actions_clipped_total"] = self._batch.episodes[0].actions_clipped  # type: ignore[union-attr]
        if self._residual_scale is not None:
            info["residual_torque_nm"] = command
        if self._more_info:
            b = self._batch
            if b.reports_law_slots:
                info.update(b.law_info_of(0))
            if b.coupled:
                info.update(b.coupled_info_of(0))
        return info


class DrillStringFieldEnv(DrillStringEnv):
    """Torsional stick-slip control of a field-length drill string, as a rig sees it.

    ## Description
    The plant is a distributed string built from its geometry (docs/specification.md section
    17): 1-6 km of drill pipe and a BHA discretised into elements of about 25 m, so the
    torsional waves that travel between the top drive and the bit, the string's own stick-slip
    period and the delay between surface and bit all follow from its length. The bit rubs on
    rock with the same Karnopp friction as the 4-DOF plant of ``DrillString-v0``. By default
    the controller sees what a rig measures: the top-drive speed and the surface torque (100 Hz,
    with noise), the bit speed by mud-pulse telemetry (one value every 5 s, 5 s late), and acts
    through a top drive with dead time, torque lag and a torque rate limit. Everything else is
    the contract of ``DrillString-v0``: actions, residual mode, rewards, ``info``, bad input,
    determinism, the native vector env.

    ## Action Space
    ``Box(-1, 1, (1,), float32)`` as in ``DrillString-v0``; the torque range is that of the top
    drive (0 to 50.8 kN m by default). Action 0 is the base controller alone in residual mode,
    and 25.4 kN m (the middle of the range) in direct mode.

    ## Observation Space
    ``Box(-50, 50, (n,), float32)``. ``observation="surface"`` (default): measured top-drive
    speed (20 rad/s), measured surface torque (the torque scale), reference bit speed
    (20 rad/s), last applied torque, then with telemetry the last bit speed received (20 rad/s;
    0 before the first) and its age (10 s), then in residual mode the base controller's torque
    and error signal. ``observation="state"``: the whole measured state instead of the first
    two, node speeds (20 rad/s, noisy) and element twists (1 rad) from the top drive down,
    padded with zeros to the deepest string the env can draw. ``observation="estimate"``: the
    surface observation, then the base controller's observer estimate of the bit speed (20
    rad/s) and of the bit-rock torque (the torque scale), computed inside its compiled law from
    the same surface signals and telemetry (``drill_env.layout.ESTIMATE_FIELDS``; the speed
    loops then run the observer of docs/observer.md beside the loop, their torque unchanged;
    a base controller without an observer is an error).

    ## Rewards
    The terms of ``DrillString-v0`` (``drill_env.rewards``), with the shipped field agent's
    weights by default (``FIELD_REWARD_WEIGHTS``: tracking 3, chattering 0.1 with a 50 kN m
    scale, stuck 0.5, torque 2, residual 0.5), so the reward is in ``[-3.5, 0]``.

    ## Starting State
    At rest, bit stuck. With ``randomize=True`` each reset draws (``FieldRandomization``) the
    WOB (50-200 kN, a 50 % chance of one step to another layer at 20-80 % of the episode), the
    reference speed (40-160 rpm), the measured depth (1,000-5,000 m: the drill pipe's length),
    the friction (``mu_a`` 0.6-1.0, ``mu_0 / mu_a`` 0.5-0.8, ``xi`` 0.3-1.0 s/rad) and the mud
    damping (0.5-2 times nominal). The controllers' model of the string is the nominal string
    at the drawn depth (the geometry is known on a rig; friction and damping are not).

    ## Episode End
    As ``DrillString-v0``.

    ## Arguments
    Those of ``DrillString-v0`` except ``uncertainty`` and ``uncertainty_reading``, with other
    defaults, and:

    | keyword | meaning | default |
    |---|---|---|
    | ``parameters`` | distributed preset (``field_2500m``, ``deep_5000m``) or parameters | ``field_2500m`` |
    | ``control_dt_s`` | decision period, s (the shipped field agent's) | 0.2 |
    | ``residual_scale_nm`` | residual torque per unit action, N m (the field agent's) | 10,000 |
    | ``measured_depth_m`` | change the string's depth (drill pipe length), m | the preset's |
    | ``controller_parameters`` | the controllers' model of the string | the plant's |
    | ``observation`` | ``"surface"``, ``"estimate"`` or ``"state"`` | ``"surface"`` |
    | ``noise_std_rad_s`` | noise of the measured speeds, rad/s | 0.05 |
    | ``torque_noise_std_nm`` | noise of the measured surface torque, N m | 250 |
    | ``sensor_period_s`` | sampling period of the surface signals, s | 0.01 |
    | ``telemetry_period_s`` | bit-speed telemetry period, s (``None``: no downhole data) | 5 |
    | ``telemetry_delay_s`` | telemetry delay, s | 5 |
    | ``telemetry_noise_std_rad_s`` | telemetry noise, rad/s | 0.1 |
    | ``actuator_dead_time_s`` | top-drive dead time, s | 0.02 |
    | ``actuator_lag_s`` | first-order torque lag, s | 0.02 |
    | ``torque_rate_limit_nm_per_s`` | torque rate limit, N m/s (``None``: none) | 100,000 |
    | ``max_torque_nm`` | top-drive torque limit, N m | 50,800 |
    | ``randomization`` | ``FieldRandomization`` ranges | see Starting State |
    | ``bit`` | ``"karnopp"`` or ``"rgd"`` (axial elements and the regenerative bit) | ``"karnopp"`` |
    | ``rgd_parameters`` | the RGD bit (``drill_env.coupled.RGD_PRESETS`` name or parameters) | ``"rgd_a"`` |
    | ``axial_top`` | ``"force"`` (``wob_n`` is the applied force at the top) or ``"hook"`` | ``"force"`` |
    | ``hook_speed_m_s`` | hook speed with ``axial_top="hook"``, m/s | ``None`` |
    | ``hook_stiffness_n_m`` | derrick/hook stiffness, N/m: 1e3 to 1e10, or ``inf`` (rigid) | ``inf`` |

    With ``bit="rgd"`` (docs/field-coupled.md) the string starts at rest on the bottom under the
    applied force, the observation ends with the weight on bit (1e5 N) and the rate of
    penetration (0.01 m/s), and ``info`` adds ``weight_on_bit_n``, ``torque_on_bit_nm``,
    ``mean_weight_on_bit_n``, ``rate_of_penetration_m_s``, ``bit_depth_m`` and
    ``bit_off_bottom``.

    ## Info
    That of ``DrillString-v0``; ``bit_speed_rad_s`` and ``top_drive_speed_rad_s`` are the true
    speeds of the bit and top-drive nodes, plus ``telemetry_bit_speed_rad_s`` and
    ``telemetry_age_s`` when telemetry is on. The estimates of a base controller's observer
    (``estimated_*``, ``estimate_error_*``) are of the 4-DOF state at the probe nodes
    (``drill_env.modes.probe_nodes``). ``env.unwrapped.string_state()`` gives the true state of
    every node now (:class:`StringState`: depths, speeds, element twists and torques), in either
    observation mode, for studies of the torsional waves along the string.

    ## Version History
    * v0: initial version.

    ## Example
    >>> import gymnasium as gym, drill_env
    >>> env = gym.make("DrillStringField-v0", randomize=False, base_controller="soft_speed")
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample() * 0)
    """

    config_type: ClassVar[type[EnvConfig]] = FieldEnvConfig

    _chain: tuple[object, Chain] | None = None  # the episode's plant and its chain

    def string_state(self) -> StringState:
        """The true state of the episode's string now, every node from the top drive (node 0)
        down to the bit (node ``n - 1``): depths, speeds, element twists and torques (copies).

        Raises:
            RuntimeError: before the first ``reset()``.
        """
        episode = self.batch.episodes[0]
        if episode is None:
            raise RuntimeError("call reset() before string_state()")
        plant = episode.scenario.plant
        if self._chain is None or self._chain[0] is not plant:
            self._chain = (plant, discretize(plant))  # type: ignore[arg-type]
        chain = self._chain[1]
        n = chain.n_nodes
        x = self.batch.x[0, : 2 * n - 1]
        speed = x[0::2].copy()
        twist = x[1::2].copy()
        torque = chain.element_stiffness_nm_rad * twist + chain.element_damping_nm_s_rad * (
            speed[:-1] - speed[1:]
        )
        return StringState(chain.node_depth_m.copy(), speed, twist, torque)
