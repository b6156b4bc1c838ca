"""``drill-gym sweep-train``: training sweeps on Ray Tune (the rl and scale extras): the bad
specs fail on one line before anything starts; a 2-trial sweep of a few hundred decisions on
the local cluster writes every trial's run folder, the summary table and the best model."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from experiments import sweep_train
from experiments.cli import main as cli_main
from experiments.spec_cli import spec_from_args

TINY = [
    "--set", "total_timesteps=200", "num_envs=2", "n_steps=50", "batch_size=50",
    "validate_every=100", "validation_episodes=1", "episode_s=10", "checkpoint_every=100",
    "--heldout-scenarios", "h01", "--no-progress",
]  # fmt: skip
"""Two rollouts of 100 decisions per trial, three validations, one held-out scenario."""


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--grid", "learning_rate="], r"--grid 'learning_rate=': the grid of learning_rate is empty"),
        (["--grid", "learning_rat=1,2"], r"unknown training setting 'learning_rat': allowed .*learning_rate"),
        (["--grid", "learning_rate=fast"], r"learning_rate = 'fast' is not a valid float"),
        (["--grid", "learning_rate=-1"], r"--learning-rate = -1.0 is out of range"),
        (["--sample", "ent_coef=normal:0:1"], r"unknown distribution 'normal': allowed uniform, loguniform, int, choice"),
        (["--sample", "learning_rate=loguniform:0:1e-3"], r"allowed LOW < HIGH and LOW > 0"),
        (["--sampler", "optuna"], r"--sampler optuna needs one or more --sample"),
        (["--sampler", "optuna", "--seeds", "1", "2", "--sample", "ent_coef=uniform:0:0.1"], r"one seed"),
        (["--samples", "0"], r"argument --samples: 0 is out of range"),
        (["--workers", "0"], r"argument --workers: 0 is out of range"),
        (["--set", "num_envs=0"], r"--num-envs = 0 is out of range: allowed an integer >= 1"),
        (["--set", "seed=3"], r"unknown training setting 'seed'"),
        (["--grid", "gamma=0.9,0.99", "--set", "gamma=0.9"], r"gamma is set more than once"),
        (["--heldout-scenarios", "h99"], r"argument --heldout-scenarios: unknown scenario 'h99'"),
        (["--grace-period", "0"], r"argument --grace-period: 0 is out of range"),
    ],
)  # fmt: skip
def test_bad_training_sweep_is_one_line_before_anything_starts(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert cli_main(["sweep-train", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("drill-gym sweep-train: error: ") and err.count("\n") == 1, err
    assert re.search(message, err), err
    assert not out.exists()


def test_the_options_are_the_spec_and_grid_and_sample_repeat() -> None:
    argv = ["--seeds", "3", "3", "4", "--grid", "gamma=0.9,0.99", "--grid", "n_steps=64,128"]
    argv += ["--sample", "ent_coef=uniform:0:0.01", "--sample", "vf_coef=choice:0.5,1"]
    spec = spec_from_args(sweep_train.SweepTrainSpec, sweep_train._parser().parse_args(argv))
    assert spec.grid == ("gamma=0.9,0.99", "n_steps=64,128") and len(spec.sample) == 2
    sweep = spec.sweep_spec()
    assert sweep.seeds == (3, 4) and dict(sweep.grid) == {
        "gamma": [0.9, 0.99],
        "n_steps": [64, 128],
    }
    assert set(sweep.samples) == {"ent_coef", "vf_coef"} and sweep.trials() == 2 * 2 * 2
    assert "n_steps" not in sweep.settings  # the grid wins over the small budget
    assert sweep_train.SweepTrainSpec().sweep_spec().settings == sweep_train.SWEEP_DEFAULTS
    assert sweep_train.SweepTrainSpec(train_budget=True).sweep_spec().settings == {}
    with pytest.raises(ValueError, match="--grid 'oops': expected NAME=VALUE"):
        sweep_train.SweepTrainSpec(grid=("oops",))


def test_two_trial_sweep_on_the_local_cluster(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two seeds, ASHA on the validation IAE ratio: each trial a training run of its own
    (TensorBoard logs, checkpoints, validation.csv, model/), the table of every trial, the
    best trial exported and scored on a held-out scenario."""
    pytest.importorskip("ray")
    pytest.importorskip("stable_baselines3")
    from agents.policy import load_policy

    out = tmp_path / "sweep"
    # No ASHA rung before the end (grace of 4 validations, 3 reported): both trials complete.
    argv = ["sweep-train", "--seeds", "1", "2", "--grace-period", "4", *TINY]
    assert cli_main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "sweep-train: 2 trials (2 seeds), 3 validations each, scheduler asha" in printed
    with (out / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(r["seed"] for r in rows) == ["1", "2"]
    for row in rows:
        run = Path(row["run_dir"])
        assert run.parent == out.resolve() / "runs"
        assert list((run / "tb").rglob("events.out.tfevents.*"))
        assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["steps_100", "steps_200"]
        validations = (run / "validation.csv").read_text().splitlines()
        assert len(validations) == 1 + int(row["validations"]) == 4
        best_line = min(validations[1:], key=lambda line: float(line.split(",")[1]))
        assert float(row["best_iae_ratio"]) == pytest.approx(float(best_line.split(",")[1]))
        assert (run / "model" / "policy.safetensors").is_file()
        assert row["stopped_early"] == "False"
    summary = json.loads((out / "summary.json").read_text())
    best = min(rows, key=lambda r: float(r["best_iae_ratio"]))
    assert summary["best"]["trial"] == best["trial"]
    scored = [r for r in rows if r["heldout_iae_ratio"]]
    assert [r["trial"] for r in scored] == [best["trial"]]  # --heldout best
    policy = load_policy(out / "best_model")
    assert "sweep-train" in policy.metadata["source"]
    table = (out / "trials.md").read_text()
    assert table.startswith("| trial | seed | validations | decisions | best val. IAE ratio |")
    assert table.count("\n") == 4


@pytest.mark.slow
def test_optuna_sampler_with_the_median_rule(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    pytest.importorskip("optuna")
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "optuna"
    argv = ["sweep-train", "--sampler", "optuna", "--samples", "2", "--scheduler", "median"]
    argv += ["--sample", "learning_rate=loguniform:1e-4:1e-3", "--heldout", "none"]
    assert cli_main([*argv, *TINY, "--out", str(out)]) == 0
    with (out / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 and all(1e-4 <= float(r["learning_rate"]) <= 1e-3 for r in rows)
    assert not any(r["heldout_iae_ratio"] for r in rows)
