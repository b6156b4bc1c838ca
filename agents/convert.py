"""Convert a Stable-Baselines3 ``model.zip`` (the earlier model format) to the portable one.

``model.zip`` is a pickle: reading it runs any code its author put in it. Convert only files
you made yourself or got from a source you trust; the result (``config.json``,
``policy.npz``, ``obs_norm.npz``) can then be shared and loaded without that risk::

    python -m agents.convert runs/old/model runs/old/model_portable --trust-pickle

The source folder holds ``model.zip`` with the ``config.json`` (format 1) and
``obs_norm.npz`` written beside it by earlier versions of ``drill-gym train``. The destination
may be the source folder itself (``model.zip`` is then left in place; delete it yourself).
Needs the ``[rl]`` extra (torch, Stable-Baselines3).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from agents.policy import LEGACY_MODEL_FILE, PICKLE_RISK, ResidualPolicy, load_policy

__all__ = ["convert_sb3_model", "main"]


def convert_sb3_model(
    source: str | Path, destination: str | Path, *, trust_pickle: bool = False
) -> ResidualPolicy:
    """Load the SB3 model in ``source`` (unpickling it) and write it to ``destination`` in the
    portable format.

    Args:
        source: The old model folder (or its ``model.zip``).
        destination: The new model folder.
        trust_pickle: Must be True: you accept that unpickling runs the file's code.

    Returns:
        The converted policy (as saved).

    Raises:
        ValueError: ``trust_pickle`` is False, or the source is not a valid SB3 model.
    """
    src = Path(source)
    if not trust_pickle:
        raise ValueError(
            f"converting {str(src)!r} reads a Stable-Baselines3 {LEGACY_MODEL_FILE}: "
            f"{PICKLE_RISK}; pass trust_pickle=True (--trust-pickle) only for a file you trust"
        )
    folder = src if src.is_dir() else src.parent
    policy = load_policy(folder / LEGACY_MODEL_FILE, trust_pickle=True)
    policy.metadata["source"] = (
        f"converted from a Stable-Baselines3 {LEGACY_MODEL_FILE} by agents.convert"
    )
    policy.save(destination)
    return policy


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m agents.convert SOURCE DESTINATION --trust-pickle``."""
    parser = argparse.ArgumentParser(
        prog="python -m agents.convert",
        description=(
            "Convert a Stable-Baselines3 model.zip (with its config.json and obs_norm.npz) to "
            "the portable model format (config.json, policy.npz, obs_norm.npz), which loads "
            "without running code."
        ),
    )
    parser.add_argument("source", help="the old model folder (with model.zip) or its model.zip")
    parser.add_argument("destination", help="the new model folder (may be the same folder)")
    parser.add_argument(
        "--trust-pickle",
        action="store_true",
        help=f"required: model.zip is a pickle, and {PICKLE_RISK}; "
        "pass it only for a file you made yourself or got from a source you trust",
    )
    args = parser.parse_args(list(argv) if argv is not None else None)
    if not args.trust_pickle:
        parser.error(f"--trust-pickle is required: model.zip is a pickle, and {PICKLE_RISK}")
    policy = convert_sb3_model(args.source, args.destination, trust_pickle=True)
    print(f"converted {policy.name} from {args.source} to {args.destination}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
