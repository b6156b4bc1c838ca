"""Train the shipped agents at the default budget and time them.

Runs, one after the other and with the default :class:`agents.config.TrainConfig`:

* ``residual_ppo``: PPO residual on top of the proposed adaptive SMC (the shipped agent);
* ``direct_ppo``: the same PPO and seed setting the whole torque from scratch
  (``--base-controller none``), for contrast, with the settings its shipped model records
  (``agents/models/direct_ppo/config.json``: 2 M decisions and the reward of that run);

prints the wall time of each, draws the learning curves, and with ``--ship`` copies the two
final models to ``agents/models/`` and the figure to ``docs/reports/figures/``. Then
``drill-gym evaluate`` scores them on the held-out set.

Run from the repository root::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/train_budget.py --ship

CI machines have 2 cores; training uses one for the simulation and one for torch.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import time
from pathlib import Path
from typing import Any

from agents.config import TrainConfig
from agents.policy import DEFAULT_MODEL_DIR
from agents.train import train
from experiments.plots import plot_learning_curves

FIGURE = Path("docs/reports/figures/residual_ppo_learning_curve.png")


def _shipped_settings(name: str) -> dict[str, Any]:
    """The training settings recorded in a shipped model's ``config.json`` (checked JSON)."""
    record = json.loads((DEFAULT_MODEL_DIR / name / "config.json").read_text())
    settings = dict(record["train_config"])
    settings.pop("run_dir", None)
    settings.pop("save_dir", None)
    return settings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="runs/budget", help="folder of the two runs")
    parser.add_argument("--seed", type=int, default=TrainConfig.seed, help="seed of both runs")
    parser.add_argument(
        "--ship", action="store_true", help="copy the models to agents/models/ and the figure"
    )
    parser.add_argument(
        "--only", choices=("residual_ppo", "direct_ppo"), default=None, help="train one run only"
    )
    args = parser.parse_args()
    out = Path(args.out)
    base = TrainConfig(seed=args.seed, progress_bar=False)
    configs = {
        "residual_ppo": dataclasses.replace(base, run_dir=str(out / "residual_ppo")),
        "direct_ppo": dataclasses.replace(
            TrainConfig.from_dict(_shipped_settings("direct_ppo")),
            seed=args.seed,
            progress_bar=False,
            run_dir=str(out / "direct_ppo"),
        ),
    }
    if args.only:
        configs = {args.only: configs[args.only]}
    times: dict[str, float] = {}
    for name, config in configs.items():
        t0 = time.perf_counter()
        model_dir = train(config)
        times[name] = time.perf_counter() - t0
        record = json.loads((model_dir / "config.json").read_text())
        print(
            f"{name}: {times[name]:.0f} s wall ({record['wall_time_s']} s in PPO.learn), "
            f"{record['run_timesteps']} decisions; model at {record['timesteps']} ({record['selected']})"
        )
        if args.ship:
            target = DEFAULT_MODEL_DIR / name
            if target.exists():
                shutil.rmtree(target)
            shutil.copytree(model_dir, target)
            print(f"  shipped to {target}")
    runs = {name: out / name for name in ("residual_ppo", "direct_ppo") if (out / name).is_dir()}
    figure = FIGURE if args.ship else out / FIGURE.name
    plot_learning_curves(runs, figure, "PPO on the randomised training scenarios (validation set)")
    print(f"learning curves: {figure}")


if __name__ == "__main__":
    main()
