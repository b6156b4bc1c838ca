"""Convert a model of an earlier format to the current one (``config.json`` and safetensors).

Two sources:

* a model folder of the previous format (format 2: ``config.json``, ``policy.npz``,
  ``obs_norm.npz``), read without pickle; the arrays are copied bit for bit;
* a Stable-Baselines3 ``.zip`` (format 1) with the ``config.json`` and ``obs_norm.npz``
  written beside it by earlier versions of ``drill-gym train``. It is a pickle: reading it
  runs any code its author put in it, so it is read only with ``trust_pickle=True``
  (``--trust-pickle``), and only the file named: a folder is never searched for one.

::

    drill-gym convert runs/old/model runs/old/model_v3
    drill-gym convert runs/older/model/model.zip runs/older/model_v3 --trust-pickle

The destination may be the source folder itself (the old files are then left in place;
delete them yourself), a new or empty folder, or a model folder (its model files are
replaced); any other folder is refused before anything is read. A ``.zip`` needs the ``[rl]``
extra (torch, Stable-Baselines3).
"""

from __future__ import annotations

from pathlib import Path

from agents.policy import (
    LEGACY_MODEL_FILE,
    PICKLE_RISK,
    ResidualPolicy,
    is_model_folder,
    load_policy,
)

__all__ = ["convert_model", "convert_sb3_model"]


def convert_model(
    source: str | Path, destination: str | Path, *, trust_pickle: bool = False
) -> ResidualPolicy:
    """Read the model ``source`` names and write it to ``destination`` in the current format.

    Args:
        source: A model folder (or a file in it) of the current or previous format, or a
            Stable-Baselines3 ``.zip`` file.
        destination: The new model folder.
        trust_pickle: Read the ``.zip`` file ``source`` names (unpickling it runs its code).
            Covers that file only: with a folder as ``source`` nothing is unpickled.

    Returns:
        The converted policy (as saved).

    Raises:
        FileNotFoundError: ``source`` does not exist or misses a file.
        ValueError: A pickle without ``trust_pickle`` (or found in a folder rather than
            named), an invalid source, or a destination holding other files; one line.
    """
    src, dst = Path(source), Path(destination)
    if not src.exists():
        raise FileNotFoundError(
            f"{str(src)!r} does not exist: expected a model folder or a Stable-Baselines3 .zip"
        )
    pickled = src.is_file() and src.suffix == ".zip"
    if pickled and not trust_pickle:
        raise ValueError(
            f"{str(src)!r} is a Stable-Baselines3 model: {PICKLE_RISK}; pass trust_pickle=True "
            "(--trust-pickle) only for a file you trust"
        )
    folder = src.parent if src.is_file() else src
    named = folder / LEGACY_MODEL_FILE
    if trust_pickle and not pickled and named.is_file() and not is_model_folder(folder):
        raise ValueError(
            f"{str(src)!r} is not a .zip file: --trust-pickle covers only the file you name, "
            f"never a folder's contents; name the file itself (such as {str(named)!r})"
        )
    _check_destination(dst, folder)
    policy = load_policy(src, trust_pickle=pickled)
    if pickled:
        policy.metadata["source"] = (
            f"converted from a Stable-Baselines3 {src.name} by drill-gym convert"
        )
    policy.save(dst)
    return policy


convert_sb3_model = convert_model
"""Deprecated name of :func:`convert_model`."""


def _check_destination(destination: Path, source_folder: Path) -> None:
    """Refuse a destination whose files are not ours to replace."""
    if destination.is_symlink() or (destination.exists() and not destination.is_dir()):
        raise ValueError(
            f"destination {str(destination)!r} exists and is not a folder: expected a new "
            "folder, an empty one, a model folder or the source folder"
        )
    if not destination.exists() or destination.resolve() == source_folder.resolve():
        return
    if any(destination.iterdir()) and not is_model_folder(destination):
        raise ValueError(
            f"destination {str(destination)!r} holds other files: expected a new folder, an "
            "empty one, a model folder or the source folder (nothing was written)"
        )
