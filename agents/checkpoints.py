"""Training checkpoints of ``drill-gym train`` that are read without pickle.

A checkpoint is a folder ``{run_dir}/checkpoints/steps_{N}/`` (``N`` decisions trained):

* ``config.json``, ``policy.safetensors``, ``obs_norm.safetensors``: the policy at that point
  as a portable model (:func:`agents.policy.export_policy`; ``drill-gym evaluate`` takes the
  folder);
* ``training_state.safetensors``: what training needs to continue: every parameter of the
  SB3 policy (actor, value network, log-std) as ``policy/{name}``, and Adam's state per
  parameter (``adam/{i}/step``, ``adam/{i}/exp_avg``, ``adam/{i}/exp_avg_sq``);
* ``vecnormalize.safetensors``: VecNormalize's running statistics (``obs_mean``, ``obs_var``,
  ``obs_count``, ``ret_mean``, ``ret_var``, ``ret_count``);
* ``training.json``: ``format`` (3), ``num_timesteps``, ``n_updates`` and whether Adam had
  state, written last.

The folder is written under a temporary name and renamed when complete. Loading builds a
fresh PPO model from the run's settings and fills it: every array is read by
:func:`agents.model_format.read_safetensors` (checked names, shapes, dtypes, sizes; no
pickle). Checkpoints of the previous format (``training.json`` of format 2, ``.npz`` arrays)
are read by :func:`agents.legacy_format.read_npz`. Older runs wrote SB3's pickled
``rl_model_{N}_steps.zip`` and ``rl_model_vecnormalize_{N}_steps.pkl``; they are found here
and resumed only when ``--trust-pickle`` names them (:func:`agents.train.train`).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Final

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, Field

from agents.legacy_format import PREVIOUS_FORMAT, read_npz
from agents.model_format import (
    FORMAT_VERSION,
    STRICT,
    Count,
    read_json,
    read_safetensors,
    validate_json,
    write_safetensors,
)
from agents.policy import export_policy
from drill_env.files import write_text
from drill_env.validation import shown

__all__ = [
    "CHECKPOINT_DIR",
    "Checkpoint",
    "find_last_checkpoint",
    "load_checkpoint",
    "save_checkpoint",
]

CHECKPOINT_DIR: Final = "checkpoints"
PREFIX: Final = "steps_"
TRAINING_FILE: Final = "training.json"
STATE_FILE: Final = "training_state.safetensors"
VECNORM_FILE: Final = "vecnormalize.safetensors"
LEGACY_STATE_FILE: Final = "training_state.npz"
LEGACY_VECNORM_FILE: Final = "vecnormalize.npz"
LEGACY_PREFIX: Final = "rl_model"
_ADAM_KEYS: Final = ("step", "exp_avg", "exp_avg_sq")


@dataclass(frozen=True)
class Checkpoint:
    """One checkpoint of a run.

    Attributes:
        path: The checkpoint folder, or an old run's pickled ``rl_model_{N}_steps.zip``.
        steps: Decisions trained when it was written.
        legacy_norm: For an old checkpoint, its pickled VecNormalize file (or None).
        pickled: Whether it is an old pickled SB3 checkpoint (``path`` is a file).
    """

    path: Path
    steps: int
    legacy_norm: Path | None = None
    pickled: bool = False

    @property
    def legacy(self) -> bool:
        """Whether it is an old pickled SB3 checkpoint."""
        return self.pickled

    @property
    def pickles(self) -> tuple[Path, ...]:
        """The pickled files that resuming from it reads (none for a checkpoint folder)."""
        if not self.pickled:
            return ()
        return (self.path,) if self.legacy_norm is None else (self.path, self.legacy_norm)


def find_last_checkpoint(run_dir: Path) -> Checkpoint | None:
    """The checkpoint of ``run_dir`` with the most decisions (complete folders only; an old
    pickled one only when it has more decisions than every folder)."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    found: list[Checkpoint] = []
    if not folder.is_dir():
        return None
    for path in folder.iterdir():
        match = re.fullmatch(rf"{PREFIX}(\d+)", path.name)
        if match and path.is_dir() and (path / TRAINING_FILE).is_file():
            found.append(Checkpoint(path, int(match.group(1))))
            continue
        match = re.fullmatch(rf"{LEGACY_PREFIX}_(\d+)_steps\.zip", path.name)
        if match and path.is_file():
            steps = int(match.group(1))
            norm = folder / f"{LEGACY_PREFIX}_vecnormalize_{steps}_steps.pkl"
            found.append(Checkpoint(path, steps, norm if norm.is_file() else None, True))
    if not found:
        return None
    return max(found, key=lambda c: (c.steps, not c.legacy))


def _parameters(model: Any) -> tuple[dict[str, Any], list[Any]]:
    """The policy's state dict and the optimizer's parameters in its order."""
    state = dict(model.policy.state_dict())
    params = [p for group in model.policy.optimizer.param_groups for p in group["params"]]
    return state, params


def _running_stats(venv: Any) -> tuple[Any, Any]:
    from stable_baselines3.common.vec_env import VecNormalize

    if not isinstance(venv, VecNormalize):
        raise TypeError(f"expected a VecNormalize environment, got {type(venv).__name__}")
    return venv.obs_rms, venv.ret_rms


def save_checkpoint(
    model: Any, venv: Any, folder: Path, *, policy: dict[str, Any] | None = None
) -> Path:
    """Write a checkpoint folder (see the module docstring) of ``model`` and ``venv``.

    Args:
        model: The PPO model.
        venv: Its VecNormalize environment.
        folder: The checkpoint folder (replaced if it exists).
        policy: Keywords of :func:`agents.policy.export_policy` (``name``, ``env_kwargs``,
            normalisation statistics, ``metadata``) for the portable model inside.

    Returns:
        The folder.
    """

    tmp = folder.with_name(folder.name + ".partial")
    if tmp.exists():
        shutil.rmtree(tmp)
    export_policy(model, tmp, **(policy or {"name": "checkpoint", "env_kwargs": {}}))
    state, params = _parameters(model)
    arrays: dict[str, npt.NDArray[Any]] = {
        f"policy/{k}": v.detach().cpu().numpy() for k, v in state.items()
    }
    opt_state = model.policy.optimizer.state_dict()["state"]
    for i in range(len(params)):
        entry = opt_state.get(i)
        if entry is None:
            continue
        unknown = sorted(set(entry) - set(_ADAM_KEYS))
        if unknown:
            raise ValueError(f"cannot checkpoint optimizer state {unknown}: only Adam's is saved")
        for key in _ADAM_KEYS:
            arrays[f"adam/{i}/{key}"] = np.asarray(entry[key].detach().cpu().numpy())
    with_adam = bool(opt_state)
    if with_adam and len(opt_state) != len(params):
        raise ValueError("cannot checkpoint an optimizer with state for only some parameters")
    write_safetensors(tmp / STATE_FILE, arrays)
    obs_rms, ret_rms = _running_stats(venv)
    write_safetensors(
        tmp / VECNORM_FILE,
        {
            "obs_mean": obs_rms.mean,
            "obs_var": obs_rms.var,
            "obs_count": np.asarray(obs_rms.count, np.float64),
            "ret_mean": np.asarray(ret_rms.mean, np.float64),
            "ret_var": np.asarray(ret_rms.var, np.float64),
            "ret_count": np.asarray(ret_rms.count, np.float64),
        },
    )
    record = {
        "format": FORMAT_VERSION,
        "num_timesteps": int(model.num_timesteps),
        "n_updates": int(model._n_updates),
        "optimizer_state": with_adam,
    }
    write_text(tmp / TRAINING_FILE, json.dumps(record, indent=2) + "\n")
    if folder.exists():
        shutil.rmtree(folder)
    os.replace(tmp, folder)
    return folder


class _TrainingRecord(BaseModel):
    """``training.json``: how far training went (format 2: ``.npz`` arrays beside it)."""

    model_config = STRICT
    format: Annotated[int, Field(ge=PREVIOUS_FORMAT, le=FORMAT_VERSION)]
    num_timesteps: Count
    n_updates: Count
    optimizer_state: bool


def _read_training_record(folder: Path) -> _TrainingRecord:
    path = folder / TRAINING_FILE
    return validate_json(_TrainingRecord, read_json(path), str(path))


def load_checkpoint(model: Any, venv: Any, folder: Path) -> int:
    """Fill a fresh PPO ``model`` (built with the run's settings) and its VecNormalize
    ``venv`` from a checkpoint folder; sets ``model.num_timesteps``.

    Returns:
        The decisions trained when the checkpoint was written.

    Raises:
        FileNotFoundError: A file of the checkpoint is missing.
        ValueError: A file is corrupt or does not fit the model (other settings than the
            run's: the message names the file and the array).
    """
    import torch as th

    record = _read_training_record(folder)
    match = re.fullmatch(rf"{PREFIX}(\d+)", folder.name)
    if match and int(match.group(1)) != record.num_timesteps:
        raise ValueError(
            f"{str(folder / TRAINING_FILE)!r}: field num_timesteps = {record.num_timesteps} "
            f"does not match the folder name {shown(folder.name)}"
        )
    legacy = record.format == PREVIOUS_FORMAT
    read = read_npz if legacy else read_safetensors
    state_file = folder / (LEGACY_STATE_FILE if legacy else STATE_FILE)
    vecnorm_file = folder / (LEGACY_VECNORM_FILE if legacy else VECNORM_FILE)
    state, params = _parameters(model)
    expected = {f"policy/{k}": tuple(v.shape) for k, v in state.items()}
    if record.optimizer_state:
        for i, p in enumerate(params):
            expected[f"adam/{i}/step"] = ()
            expected[f"adam/{i}/exp_avg"] = tuple(p.shape)
            expected[f"adam/{i}/exp_avg_sq"] = tuple(p.shape)
    what = "training state (policy parameters and Adam state) for this run's settings"
    arrays = read(state_file, expected, what)
    size = int(model.observation_space.shape[0])
    vec_shapes = {
        "obs_mean": (size,),
        "obs_var": (size,),
        "obs_count": (),
        "ret_mean": (),
        "ret_var": (),
        "ret_count": (),
    }
    stats = read(vecnorm_file, vec_shapes, "VecNormalize statistics")
    where = str(vecnorm_file)
    for key in ("obs_var", "ret_var"):
        if np.any(stats[key] < 0):
            raise ValueError(f"{where!r}: array {key} has negative entries: allowed >= 0")
    for key in ("obs_count", "ret_count"):
        if not stats[key] > 0:
            raise ValueError(f"{where!r}: array {key} = {shown(float(stats[key]))}: allowed > 0")
    with th.no_grad():
        model.policy.load_state_dict(
            {k: th.as_tensor(arrays[f"policy/{k}"], dtype=v.dtype) for k, v in state.items()}
        )
    optimizer = model.policy.optimizer
    opt_state: dict[int, dict[str, Any]] = {}
    if record.optimizer_state:
        for i, p in enumerate(params):
            opt_state[i] = {
                "step": th.tensor(float(arrays[f"adam/{i}/step"]), dtype=th.float32),
                "exp_avg": th.as_tensor(arrays[f"adam/{i}/exp_avg"], dtype=p.dtype),
                "exp_avg_sq": th.as_tensor(arrays[f"adam/{i}/exp_avg_sq"], dtype=p.dtype),
            }
    optimizer.load_state_dict(
        {"state": opt_state, "param_groups": optimizer.state_dict()["param_groups"]}
    )
    obs_rms, ret_rms = _running_stats(venv)
    obs_rms.mean = stats["obs_mean"].copy()
    obs_rms.var = stats["obs_var"].copy()
    obs_rms.count = float(stats["obs_count"])
    ret_rms.mean = np.float64(stats["ret_mean"])
    ret_rms.var = np.float64(stats["ret_var"])
    ret_rms.count = float(stats["ret_count"])
    model.num_timesteps = record.num_timesteps
    model._n_updates = record.n_updates
    return record.num_timesteps
