"""``drill-gym sweep-train``: training sweeps on Ray Tune (the rl and scale extras): the bad
specs fail on one line before anything starts; a 2-trial sweep of a few hundred decisions on
the local cluster writes every trial's run folder, the summary table and the best model."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
import time
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
NO_VALIDATION = [
    "--set", "total_timesteps=200", "num_envs=2", "n_steps=50", "batch_size=50",
    "validate_every=0", "validation_episodes=1", "episode_s=10", "checkpoint_every=100",
    "--no-progress",
]  # fmt: skip
"""As :data:`TINY` without validations during training (the field agent's recipe)."""


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
    assert (
        spec.grid == ("gamma=0.9,0.99", "n_steps=64,128")
        and spec.sample is not None
        and len(spec.sample) == 2
    )
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
    # No ASHA rung before the end (a grace of 4 validations, more than the 2 reported): both
    # trials complete.
    argv = ["sweep-train", "--seeds", "1", "2", "--grace-period", "4", *TINY]
    assert cli_main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "sweep-train: 2 trials (2 seeds), 2 validations each, scheduler asha" in printed
    with (out / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(r["seed"] for r in rows) == ["1", "2"]
    for row in rows:
        run = Path(row["run_dir"])
        assert run.parent == out.resolve() / "runs"
        assert list((run / "tb").rglob("events.out.tfevents.*"))
        assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["steps_100", "steps_200"]
        validations = (run / "validation.csv").read_text().splitlines()
        assert len(validations) == 1 + int(row["validations"]) == 3
        best_line = min(validations[1:], key=lambda line: float(line.split(",")[1]))
        assert float(row["best_iae_ratio"]) == pytest.approx(float(best_line.split(",")[1]))
        assert (run / "model" / "policy.safetensors").is_file()
        kept = load_policy(run / "model").metadata
        assert int(row["kept_at_timesteps"]) == kept["timesteps"]
        assert float(row["kept_score"]) == pytest.approx(kept["validation_score"], abs=1e-5)
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


def test_a_sweep_without_validations_reports_its_final_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``validate_every`` 0 with the default scheduler (ASHA), Tune's metric check on: each
    trial reports the validation of its final model once, at its end."""
    pytest.importorskip("ray")
    pytest.importorskip("stable_baselines3")
    monkeypatch.delenv("TUNE_DISABLE_STRICT_METRIC_CHECKING", raising=False)
    out = tmp_path / "sweep"
    argv = ["sweep-train", "--seeds", "1", "2", "--heldout", "none", *NO_VALIDATION]
    assert cli_main([*argv, "--out", str(out)]) == 0
    assert "2 trials (2 seeds), 1 validations each, scheduler asha" in capsys.readouterr().out
    with (out / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(r["seed"] for r in rows) == ["1", "2"]
    for row in rows:
        assert row["validations"] == "1" and row["timesteps"] == "200", row
        assert float(row["best_iae_ratio"]) == float(row["last_iae_ratio"]) > 0
        assert row["stopped_early"] == "False" and not row["error"]
        assert not (Path(row["run_dir"]) / "validation.csv").exists()
    best = min(rows, key=lambda r: float(r["best_iae_ratio"]))
    assert json.loads((out / "summary.json").read_text())["best"]["trial"] == best["trial"]


def test_the_final_validation_is_the_training_validation(tmp_path: Path) -> None:
    """:func:`final_validation` of a model scores it as the training's own validation does
    (its ``validation.csv`` line of the final model, written with five decimals), the
    severity term of the selection score included."""
    pytest.importorskip("stable_baselines3")
    from agents.config import TrainConfig
    from agents.train import VALIDATION_COLUMNS, train

    config = TrainConfig(
        total_timesteps=100, num_envs=2, n_steps=50, batch_size=50, validate_every=100,
        validation_episodes=2, episode_s=10.0, checkpoint_every=0, tensorboard=False,
        run_dir=str(tmp_path / "run"), validation_severity_weight=3.0,
    )  # fmt: skip
    model = train(config, progress=False)
    csv_file = tmp_path / "run" / "validation.csv"
    assert csv_file.read_text().partition("\n")[0] == ",".join(VALIDATION_COLUMNS[False])
    recorded = sweep_train._validations(csv_file)[-1]
    result = sweep_train.final_validation(config, model)
    assert result["timesteps"] == recorded["timesteps"] == 100
    assert set(result) == set(recorded) == set(VALIDATION_COLUMNS[False])
    for key in VALIDATION_COLUMNS[False][1:]:
        assert result[key] == pytest.approx(recorded[key], abs=1e-5), key


def test_resume_needs_the_same_sweep_in_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--resume`` without a sweep in --out, with other options than the sweep's, and a new
    sweep in a folder that holds one: one line each, before anything starts."""
    pytest.importorskip("ray")
    out = tmp_path / "out"
    assert cli_main(["sweep-train", "--resume", "--out", str(out)]) == 2
    assert "--resume: no sweep to resume in" in capsys.readouterr().err
    assert not out.exists()
    spec = sweep_train.SweepTrainSpec(seeds=(1, 2)).sweep_spec()
    (out / "tune").mkdir(parents=True)
    (out / "tune" / "tuner.pkl").write_bytes(b"")  # never read: the spec differs
    (out / "sweep.json").write_text(json.dumps(sweep_train._spec_record(spec)))
    assert cli_main(["sweep-train", "--seeds", "1", "--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "started with other settings (seeds differ)" in err, err
    assert cli_main(["sweep-train", "--seeds", "1", "2", "--out", str(out)]) == 2
    assert "already holds a sweep: pass --resume" in capsys.readouterr().err
    # the same sweep: Tune's state is pickle, restored only when --trust-pickle names its folder
    same = ["sweep-train", "--seeds", "1", "2", "--resume", "--out", str(out)]
    for trust in ([], ["--trust-pickle", str(tmp_path)], ["--trust-pickle", str(out / "x")]):
        assert cli_main([*same, *trust]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "pass --trust-pickle" in err and "any code" in err, err
    assert cli_main(["sweep-train", "--trust-pickle", str(out / "tune"), "--out", str(out)]) == 2
    assert "it needs --resume" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["sweep.json", "tune"]


@pytest.mark.slow
def test_a_killed_sweep_resumes_only_its_missing_trials(tmp_path: Path) -> None:
    """Kill a two-trial sweep (one trial at a time) while its second trial trains, then run
    the same command with --resume: the same two trials, the first kept as it was, the
    second finished from its run folder (its checkpoints or its final model)."""
    pytest.importorskip("ray")
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "sweep"
    argv = [sys.executable, "-m", "experiments.cli", "sweep-train", "--seeds", "1", "2"]
    argv += ["--workers", "1", "--heldout", "none", *NO_VALIDATION, "--out", str(out)]
    argv[argv.index("total_timesteps=200")] = "total_timesteps=2000"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("TUNE_DISABLE_STRICT_METRIC_CHECKING", None)
    sweep = subprocess.Popen(
        argv, env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.monotonic() + 600
    try:
        while time.monotonic() < deadline and sweep.poll() is None:
            runs = sorted((out / "runs").glob("*__seed*"))
            finished = [r for r in runs if (r / "model").is_dir()]
            training = [r for r in runs if r not in finished and list(r.glob("checkpoints/*"))]
            if finished and training:
                break
            time.sleep(0.1)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
        sweep.wait()
    assert finished and training, "the sweep ended before it could be interrupted"
    assert not (out / "trials.csv").exists()
    first = finished[0] / "model" / "policy.safetensors"
    kept = (first.stat().st_mtime_ns, (finished[0] / "progress.csv").read_text())
    time.sleep(2.0)  # the interrupted trial's worker notices that its cluster is gone
    interrupted = not (training[0] / "model").is_dir()
    refused = subprocess.run([*argv, "--resume"], env=env, capture_output=True, text=True)
    assert refused.returncode == 2 and "--trust-pickle" in refused.stderr  # pickles: opt in
    trusted = [*argv, "--resume", "--trust-pickle", str(out / "tune")]
    done = subprocess.run(trusted, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    with (out / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(Path(r["run_dir"]).name for r in rows) == sorted(r.name for r in runs)
    assert all(r["timesteps"] == "2000" and r["validations"] == "1" for r in rows), rows
    assert (first.stat().st_mtime_ns, (finished[0] / "progress.csv").read_text()) == kept
    assert (training[0] / "model" / "policy.safetensors").is_file()
    if interrupted:  # it continued from its last checkpoint
        assert list(training[0].glob("progress-resumed-at-*.csv"))


def test_a_broken_validation_record_is_named_not_a_traceback(tmp_path: Path) -> None:
    csv_file = tmp_path / "validation.csv"
    csv_file.write_text("timesteps,iae_ratio,score\n100,0.9,1.0\n200,x,1\n")
    with pytest.raises(ValueError, match=r"validation.csv': line 3 is not a validation record"):
        sweep_train._validations(csv_file)
    csv_file.write_text("timesteps,iae_ratio,score\n100,0.9,1.0\n")
    assert sweep_train._validations(csv_file) == [
        {"timesteps": 100, "iae_ratio": 0.9, "score": 1.0}
    ]
