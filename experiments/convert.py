"""``drill-gym convert OLD NEW --trust-pickle``: an old Stable-Baselines3 ``model.zip`` to the
portable model format (:func:`agents.convert.convert_sb3_model`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Final

from experiments.arguments import ArgumentParser

__all__ = ["DESCRIPTION", "main"]

DESCRIPTION: Final = """\
Convert a model folder of an earlier version (a Stable-Baselines3 model.zip with its
config.json and obs_norm.npz) to the portable model format (config.json, policy.npz,
obs_norm.npz), which loads without running any code and needs only NumPy.

model.zip is a pickle: reading it runs any code its author put in it. Convert only files you
made yourself or got from a source you trust; the result can then be shared safely. NEW may be
OLD itself (model.zip is then left in place). Needs the rl extra (torch, Stable-Baselines3).

example:
  drill-gym convert runs/old/model runs/old/model_portable --trust-pickle
"""


def _parser() -> ArgumentParser:
    from agents.policy import PICKLE_RISK

    parser = ArgumentParser(prog="drill-gym convert", description=DESCRIPTION)
    parser.add_argument("old", metavar="OLD", help="the old model folder (with model.zip)")
    parser.add_argument("new", metavar="NEW", help="the new model folder (may be OLD)")
    parser.add_argument(
        "--trust-pickle",
        action="store_true",
        help=f"required: model.zip is a pickle, and {PICKLE_RISK}; pass it only for a file "
        "you made yourself or got from a source you trust",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Convert; returns the exit code.

    Raises:
        ValueError: The source is not a valid Stable-Baselines3 model.
        FileNotFoundError: No model.zip in OLD.
    """
    from agents.policy import PICKLE_RISK

    parser = _parser()
    args = parser.parse_args(list(argv) if argv is not None else None)
    if not args.trust_pickle:
        parser.fail("--trust-pickle", f"is required: model.zip is a pickle, and {PICKLE_RISK}")
    old = Path(args.old)
    if not (old.is_dir() or old.is_file()):
        parser.error(
            f"OLD = {args.old!r} does not exist: expected an old model folder (with model.zip) "
            "or its model.zip"
        )
    from agents.convert import convert_sb3_model

    policy = convert_sb3_model(args.old, args.new, trust_pickle=True)
    print(f"converted {policy.name} from {args.old} to {args.new}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
