"""``drill-gym train``: the command line of the residual PPO training (:mod:`agents.train`).

Every field of :class:`agents.config.TrainConfig` is an option (its help is the field's
docstring); ``--out`` is another name of ``--run-dir``, and ``--no-progress`` prints no line per
rollout or validation. Needs the ``[rl]`` extra (torch, Stable-Baselines3) to train; ``--help``
works without it.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Final

from agents.config import config_from_namespace, config_parser
from agents.train import train
from experiments.arguments import ArgumentParser

__all__ = ["DESCRIPTION", "main"]

DESCRIPTION: Final = """\
Train the residual PPO agent: a Stable-Baselines3 PPO policy that adds a learned torque (up to
+-20 kN m by default) to the proposed adaptive sliding-mode controller, which still runs at
every 1 ms plant step; the agent decides every 0.1 s. It trains on randomised scenarios (WOB
60-200 kN with a 50 % chance of a step, reference bit speed 4-16 rad/s, parameter uncertainty
up to 75 %, 0.1 rad/s measurement noise) in 16 strings simulated together. The defaults are
the settings of the shipped agent (agents/models/residual_ppo).

A run writes into its run folder (runs/EXP_NAME__SEED unless --run-dir or --out says
otherwise):

    config.json            the settings of the run
    progress*.csv, tb/     training statistics and TensorBoard logs with the validation ratios
    validation.csv         validation IAE, RMSD and severity relative to the base controller
    checkpoints/steps_N/   checkpoints (no pickle) every --checkpoint-every decisions and at
                           the end; --resume continues from the last one
    best/                  the best model on the validation scenarios
    model/                 the final model: config.json, policy.safetensors, obs_norm.safetensors

PPO trains in whole rollouts of n_steps x num_envs decisions, so --total-timesteps is rounded
up to whole rollouts (the first line printed says so). A run folder that already holds files
is refused unless --resume continues it or --overwrite clears it. One line is printed per
rollout (decisions, decisions per second, mean episode return) and per validation.

examples:
  drill-gym train                                    # the shipped agent's settings
  drill-gym train --total-timesteps 20000 --seed 3   # a short run (32,000 decisions)
  drill-gym train --resume --total-timesteps 4000000 # continue from the last checkpoint
  drill-gym train --base-controller none --exp-name direct_ppo  # from scratch, no SMC
"""


def _parser() -> argparse.ArgumentParser:
    parser = config_parser("drill-gym train", DESCRIPTION, parser_class=ArgumentParser)
    parser.add_argument(
        "--out",
        dest="run_dir",
        metavar="DIR",
        default=argparse.SUPPRESS,
        help="the same as --run-dir: the folder of the run (default: runs/EXP_NAME__SEED)",
    )
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="print no line per rollout or validation and no progress bar (default: they are "
        "printed)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym train [--field value ...]``; returns the exit code (``--help`` lists every
    option).

    Raises:
        ValueError: A setting out of range or that the run cannot use (one line naming the
            option; ``drill-gym`` prints it and exits with 2).
        FileNotFoundError: ``--resume`` without a checkpoint.
    """

    args = _parser().parse_args(list(argv) if argv is not None else None)
    config = config_from_namespace(args)

    out = train(config, progress=not args.no_progress)
    record = json.loads((out / "config.json").read_text())
    print(
        f"model saved to {out}: {record.get('selected')}, at {record.get('timesteps')} of "
        f"{record.get('run_timesteps')} decisions; {record.get('wall_time_s')} s of training"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
