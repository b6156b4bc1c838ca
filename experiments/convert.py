"""``drill-gym convert OLD NEW``: a model of an earlier format to the current one
(:func:`agents.convert.convert_model`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Final

from agents.convert import convert_model
from agents.policy import PICKLE_RISK
from drill_env.validation import shown
from experiments.arguments import ArgumentParser
from experiments.spec_cli import option, spec_from_args, spec_parser

__all__ = ["DESCRIPTION", "ConvertSpec", "main"]

DESCRIPTION: Final = """\
Convert a model of an earlier format to the current one (config.json, policy.safetensors,
obs_norm.safetensors), which loads without running any code and needs only NumPy:

  - a model folder of the previous format (config.json, policy.npz, obs_norm.npz): read
    without running code, the arrays copied bit for bit;
  - a Stable-Baselines3 .zip file of the first format, with the config.json and obs_norm.npz
    beside it: a pickle, read only with --trust-pickle, and only the file you name (a
    folder is never searched for one). Needs the rl extra (torch, Stable-Baselines3).

NEW may be OLD's folder itself (the old files are left in place), a new or empty folder, or a
model folder (its model files are replaced); any other folder is refused.

examples:
  drill-gym convert runs/old/model runs/old/model_v3
  drill-gym convert runs/older/model/model.zip runs/older/model_v3 --trust-pickle
"""


@dataclasses.dataclass(frozen=True)
class ConvertSpec:
    """Settings of ``drill-gym convert``; its arguments are generated from these fields."""

    old: str | None = dataclasses.field(
        default=None, metadata=option(positional=True, metavar="OLD")
    )
    """the old model folder, or a Stable-Baselines3 .zip file"""
    new: str | None = dataclasses.field(
        default=None, metadata=option(positional=True, metavar="NEW")
    )
    """the new model folder (may be OLD's folder)"""
    trust_pickle: bool = dataclasses.field(
        default=False,
        metadata=option(
            help=f"read the .zip file OLD names, a pickle: {PICKLE_RISK}; pass it only for a "
            "file you made yourself or got from a source you trust"
        ),
    )
    """read the .zip file OLD names, a pickle (:data:`agents.policy.PICKLE_RISK`)"""


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym convert", DESCRIPTION, ConvertSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """Convert; returns the exit code.

    Raises:
        ValueError: OLD is not a valid model, a pickle not covered by --trust-pickle, or NEW
            holds other files.
        FileNotFoundError: OLD or one of its files does not exist.
    """

    parser = _parser()
    spec = spec_from_args(ConvertSpec, parser.parse_args(list(argv) if argv is not None else None))
    if spec.old is None or spec.new is None:
        missing = [name for name, value in (("OLD", spec.old), ("NEW", spec.new)) if value is None]
        parser.error(f"the following arguments are required: {', '.join(missing)}")
    if spec.old.endswith(".zip") and not Path(spec.old).is_dir() and not spec.trust_pickle:
        parser.fail(
            "--trust-pickle",
            f"is required to read OLD = {shown(spec.old)}: a pickle, and {PICKLE_RISK}",
        )
    if not Path(spec.old).exists():
        parser.error(
            f"OLD = {shown(spec.old)} does not exist: expected a model folder or a Stable-Baselines3 "
            ".zip file"
        )

    policy = convert_model(spec.old, spec.new, trust_pickle=spec.trust_pickle)
    print(f"converted {policy.name} from {spec.old} to {spec.new}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
