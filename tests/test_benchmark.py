"""``drill-gym benchmark`` (:mod:`experiments.benchmark`): the versioned suites (loading,
validation, pinned content), the interquartile mean and its stratified-bootstrap interval
against a hand computation, the normalised score, and the command on a tiny suite as a user
types it."""

from __future__ import annotations

import copy
import csv
import json
import math
import os
import re
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from experiments import benchmark
from experiments.benchmark import (
    METRICS,
    SUITE_DIR,
    BenchmarkStudy,
    content_hash,
    iqm,
    iqm_interval,
    load_suite,
    make_entry,
    merge_entries,
    normalised_score,
    score_suite,
    shipped_suites,
    training_seed_table,
)
from experiments.cli import main
from experiments.heldout import CORNERS, FIELD_HELD_OUT, HELD_OUT
from experiments.spec_cli import spec_from_args
from experiments.sweep import spec_hash

ROOT = Path(__file__).resolve().parents[1]

SHIPPED_SHA256 = {
    "corners-v1": "c512af8ba929f801af8704a444bcefadd9c5c697ef27683d052712cfb614bc8a",
    "deep-v1": "67862ca23da63dd51b65cb227902c683970077bda8595c0c62db249f79fd29fd",
    "field-v1": "272d8883699f9cabaf992d6f490ddb449895dc077efab106c82b2581deba6945",
    "heldout-v1": "6521c30de01cdfc01c44b886dbe1ce3fbf57ce6ccf4422340e9d39d3dc15ba63",
    "outside-v1": "53732a798c779afcd64e2f49c2d91969a9084fc2e75aaa35f620d4a5bc31318b",
}
"""The content of every shipped suite. A shipped suite is never edited: a changed suite is a
new file ``NAME-v(N+1).json`` with a new line here, and the old one stays as it was."""


@pytest.fixture(autouse=True)
def _own_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """The users' classes a test registers stay in that test (the registry is per process)."""
    import baselines  # noqa: F401  (the built-in ones first, in their order, before the copy)
    import drill_env.control as control
    import experiments.controllers as controllers

    monkeypatch.setattr(control, "_FACTORIES", dict(control._FACTORIES))
    monkeypatch.setattr(controllers, "_LOADED", {})


# ---------------------------------------------------------------------------------- suites
def test_every_shipped_suite_is_pinned_and_unchanged() -> None:
    assert shipped_suites() == sorted(SHIPPED_SHA256)
    for label, digest in SHIPPED_SHA256.items():
        data = json.loads((SUITE_DIR / f"{label}.json").read_text())
        assert content_hash(data) == digest, f"{label}.json changed: make a new version instead"
        suite = load_suite(label)
        assert suite.sha256 == digest and suite.label == label


def test_the_content_hash_ignores_layout_and_sees_any_change() -> None:
    data = json.loads((SUITE_DIR / "heldout-v1.json").read_text())
    relaid = json.loads(json.dumps(data, indent=4, sort_keys=True))
    assert content_hash(relaid) == content_hash(data)
    changed = copy.deepcopy(data)
    changed["scenarios"][3]["seeds"][1] += 1
    assert content_hash(changed) != content_hash(data)


@pytest.mark.parametrize(
    ("label", "expected"),
    [("heldout-v1", HELD_OUT), ("corners-v1", CORNERS), ("field-v1", FIELD_HELD_OUT)],
    ids=["heldout", "corners", "field"],
)
def test_a_suite_holds_the_projects_set_at_its_first_seed(label: str, expected: Any) -> None:
    suite = load_suite(label)
    assert [s.id for s in suite.scenarios] == [s.id for s in expected]
    for mine, theirs in zip(suite.scenarios, expected, strict=True):
        assert mine.held.scenario == theirs.scenario
        assert mine.seeds[0] == theirs.seed and len(set(mine.seeds)) == 5
        assert mine.held.row() == theirs.row()  # condition, prone and the scenario's columns


def test_the_deep_suite_is_4_to_6_km_of_the_distributed_presets() -> None:
    from drill_env.distributed import DISTRIBUTED_PRESETS

    suite = load_suite("deep")
    assert suite.label == "deep-v1" and suite.env_id == "DrillStringField-v0"
    cases = [s.held.field for s in suite.scenarios]
    assert all(c is not None and 4_000 <= c.measured_depth_m <= 6_000 for c in cases)
    assert {c.parameters for c in cases if c is not None} == set(DISTRIBUTED_PRESETS)
    assert 0 < sum(s.prone for s in suite.scenarios) < len(suite.scenarios)


def test_the_outside_suite_leaves_the_field_agents_training_ranges_with_seeds_of_its_own() -> None:
    from agents.train import TRAINING_RANGES

    suite = load_suite("outside")
    assert suite.label == "outside-v1" and suite.env_id == "DrillStringField-v0"
    cases = [s.held.field for s in suite.scenarios]
    assert all(c is not None and not c.in_range(TRAINING_RANGES["wide"]) for c in cases)
    assert 0 < sum(s.prone for s in suite.scenarios) < len(suite.scenarios)
    mine = {seed for s in suite.scenarios for seed in s.seeds}
    others = {
        seed
        for label in shipped_suites()
        if label != suite.label
        for s in load_suite(label).scenarios
        for seed in s.seeds
    }
    assert len(mine) == sum(len(s.seeds) for s in suite.scenarios) and mine.isdisjoint(others)


def _tiny(tmp_path: Path, name: str = "tiny", **changes: Any) -> Path:
    """Two scenarios of heldout-v1, two seeds each, 10 s runs, as ``name-v1.json``."""
    data = json.loads((SUITE_DIR / "heldout-v1.json").read_text())
    data.update(name=name, episode_s=10.0)
    data["scenarios"] = [dict(s, seeds=s["seeds"][:2]) for s in data["scenarios"][:2]]
    data.update(changes)
    path = tmp_path / f"{name}-v{data['version']}.json"
    path.write_text(json.dumps(data))
    return path


def _scenario_change(tmp_path: Path, **changes: Any) -> Path:
    data = json.loads(_tiny(tmp_path).read_text())
    data["scenarios"][1].update(changes)
    path = tmp_path / "tiny-v1.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: _tiny(p, extra=1), r"unknown field\(s\) extra"),
        (lambda p: _tiny(p, version=2).rename(p / "tiny-v1.json"), "file name says tiny-v1, its content tiny-v2"),
        (lambda p: _tiny(p, env_id="CartPole-v1"), "field env_id = 'CartPole-v1': allowed DrillString-v0"),
        (lambda p: _tiny(p, observation="surface"), "field observation = 'surface': allowed null"),
        (lambda p: _tiny(p, episode_s=-1), r"field episode_s = -1: allowed \[1, 100000\]"),
        (lambda p: _tiny(p, episode_s=2.5), "field episode_s = 2.5: allowed a whole number of seconds"),
        (lambda p: _tiny(p, scenarios=[]), "field scenarios = \\[\\]: allowed a non-empty list"),
        (lambda p: _scenario_change(p, seeds=[1]), r"scenarios\[1\]: field seeds = \[1\]: allowed a list of at least 2"),
        (lambda p: _scenario_change(p, seeds=[4, 4]), "distinct integers"),
        (lambda p: _scenario_change(p, id="h01"), r"scenario id\(s\) h01 appear more than once"),
        (lambda p: _scenario_change(p, wob_final_n=None), "wob_step_time_s .* together with wob_final_n"),
        (lambda p: _scenario_change(p, wob_n="lots"), r"scenarios\[1\]: field wob_n = 'lots'"),
        (lambda p: (p / "broken-v1.json").write_text("{") and p / "broken-v1.json", "not JSON"),
        (lambda p: p / "absent-v1.json", "no such file"),
    ],
    ids=[
        "unknown-field", "renamed-version", "env", "observation", "episode", "fractional-episode",
        "no-scenarios",
        "one-seed", "same-seed", "same-id", "half-a-step", "not-a-number", "not-json", "missing",
    ],
)  # fmt: skip
def test_a_bad_suite_is_an_error_naming_the_file_and_field(
    tmp_path: Path, make: Any, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        load_suite(make(tmp_path))


def test_an_unknown_suite_lists_the_shipped_ones() -> None:
    with pytest.raises(ValueError, match="unknown suite 'nope': allowed corners, deep, field"):
        load_suite("nope")


# ------------------------------------------------------------------------------ statistics
def test_iqm_is_the_mean_of_the_middle_half() -> None:
    assert iqm([8.0, 1.0, 7.0, 2.0, 6.0, 3.0, 5.0, 4.0]) == pytest.approx((3 + 4 + 5 + 6) / 4)
    values = [10.0, -3.0, 0.5, 7.0, 100.0, 2.0, 2.5, -50.0, 4.0, 1.0, 3.0, 6.0]
    middle = sorted(values)[3:9]  # 12 values: 3 cut from each end
    assert iqm(values) == pytest.approx(sum(middle) / 6)


def _hand_bootstrap(strata: list[np.ndarray], resamples: int, seed: int) -> tuple[float, float]:
    """A stratified percentile bootstrap written out: every stratum resampled with
    replacement from itself, the IQM of the pooled resample (sorted, middle half)."""
    rng = np.random.default_rng(seed)
    stats = []
    for _ in range(resamples):
        pooled = np.sort(np.concatenate([rng.choice(s, size=s.size, replace=True) for s in strata]))
        cut = int(0.25 * pooled.size)
        stats.append(pooled[cut : pooled.size - cut].mean())
    return float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


def test_the_interval_matches_a_hand_stratified_bootstrap() -> None:
    rng = np.random.default_rng(7)
    strata = [
        rng.normal(loc, scale, size=5) for loc, scale in ((10, 1), (20, 3), (15, 0.5), (30, 5))
    ]
    point, low, high = iqm_interval(strata, resamples=4000, seed=1)
    assert point == pytest.approx(iqm(np.concatenate(strata)))
    hand_low, hand_high = _hand_bootstrap(strata, 4000, 2)
    width = hand_high - hand_low
    assert low == pytest.approx(hand_low, abs=0.08 * width)
    assert high == pytest.approx(hand_high, abs=0.08 * width)
    assert low <= point <= high


def test_the_strata_are_kept_apart() -> None:
    # Two scenarios, one always 0 and one always 1: a stratified resample keeps half of each,
    # so the IQM never moves; an unstratified one would.
    point, low, high = iqm_interval([np.zeros(4), np.ones(4)], resamples=500)
    assert (point, low, high) == (0.5, 0.5, 0.5)
    point, low, high = iqm_interval([np.array([0.0, 0.0, 1.0]), np.ones(3)], resamples=500)
    assert low < high


def test_an_interval_needs_two_runs_per_scenario() -> None:
    with pytest.raises(ValueError, match="at least 2 values"):
        iqm_interval([np.array([1.0, 2.0]), np.array([3.0])])


def test_the_normalised_score_runs_from_the_reference_to_the_best() -> None:
    assert normalised_score(10.0, 10.0, 4.0) == 0.0
    assert normalised_score(4.0, 10.0, 4.0) == 1.0
    assert normalised_score(7.0, 10.0, 4.0) == pytest.approx(0.5)
    assert normalised_score(13.0, 10.0, 4.0) == pytest.approx(-0.5)
    assert math.isnan(normalised_score(7.0, 10.0, 10.0))  # nobody beats the reference


def test_score_suite_on_known_runs(tmp_path: Path) -> None:
    suite = load_suite(_tiny(tmp_path))
    rows = []
    values = {"proposed": (4.0, 6.0), "better": (1.0, 3.0), "worse": (9.0, 11.0)}
    for entry, (a, b) in values.items():
        for scenario in suite.scenarios:
            for seed, value in zip(scenario.seeds, (a, b), strict=True):
                rows.append(
                    {"suite": suite.label, "entry": entry, "scenario": scenario.id, "seed": seed,
                     "prone": scenario.prone, **dict.fromkeys(METRICS, value)}
                )  # fmt: skip
    scores = {(s["entry"], s["metric"]): s for s in score_suite(suite, rows, resamples=200)}
    iae = {e: scores[(e, "iae")] for e in values}
    assert iae["proposed"]["iqm"] == pytest.approx(5.0) and iae["proposed"]["score"] == 0.0
    assert iae["better"]["iqm"] == pytest.approx(2.0) and iae["better"]["score"] == 1.0
    assert iae["worse"]["score"] == pytest.approx((5.0 - 10.0) / (5.0 - 2.0))
    assert all(s["best"] == "better" and s["reference"] == "proposed" for s in iae.values())
    assert iae["worse"]["score_low"] <= iae["worse"]["score"] <= iae["worse"]["score_high"]
    prone = sum(s.prone for s in suite.scenarios)
    assert scores[("better", "stick_slip_severity")]["runs"] == 2 * prone
    with pytest.raises(ValueError, match="reference controller 'proposed' was not run"):
        score_suite(suite, [r for r in rows if r["entry"] != "proposed"])


# -------------------------------------------------------------------------------- command
def test_the_command_scores_a_controller_a_user_class_and_an_agent(tmp_path: Path) -> None:
    suite = _tiny(tmp_path)
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "experiments.cli", "benchmark", "stiff_pi",
         "examples/custom_controller.py:SpeedPI", "agents/models/residual_ppo",
         "agents/models/field_agent", "--suites", str(suite), "--out", str(out),
         "--resamples", "200", "--no-progress"],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert {p.name for p in out.iterdir()} == {
        "scorecard.md",
        "scorecard.csv",
        "runs.csv",
        "profiles.png",
    }
    with (out / "runs.csv").open() as f:
        runs = list(csv.DictReader(f))
    entries = ["stiff_pi", "custom_controller.SpeedPI", "residual_ppo", "proposed"]
    assert sorted({r["entry"] for r in runs}) == sorted(entries)  # the field agent: another env
    assert len(runs) == len(entries) * 2 * 2
    with (out / "scorecard.csv").open() as f:
        scores = list(csv.DictReader(f))
    assert len(scores) == len(entries) * len(METRICS)
    for row in scores:
        assert row["suite"] == "tiny-v1" and row["reference"] == "proposed"
        assert float(row["ci_low"]) <= float(row["iqm"]) <= float(row["ci_high"])
    iae = {r["entry"]: r for r in scores if r["metric"] == "iae"}
    best = iae["proposed"]["best"]
    assert float(iae[best]["iqm"]) == min(float(r["iqm"]) for r in iae.values())
    if best != "proposed":  # the score is defined when some entry beats the reference
        assert float(iae["proposed"]["score"]) == 0.0 and float(iae[best]["score"]) == 1.0
    text = (out / "scorecard.md").read_text()
    assert "## tiny-v1" in text and "one training seed" in text
    assert "custom_controller.SpeedPI" in done.stdout


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--suites", "nope"], "--suites: unknown suite 'nope'"),
        (["no_such_policy"], "POLICY: unknown controller 'no_such_policy'"),
        (["examples/custom_controller.py:Nope"], "has no 'Nope'"),
        (["--resamples", "5"], r"argument --resamples: 5 is out of range: allowed \[100, 100000\]"),
        (["--controllers", "nope_xyz"], "argument --controllers: unknown controller 'nope_xyz'"),
        (["--suites", "deep", "deep-v1"], "--suites: the same suite twice: deep-v1, deep-v1"),
    ],
    ids=["suite", "policy", "user-class", "resamples", "controllers", "twice"],
)
def test_a_bad_option_is_one_line_and_exit_code_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code = main(["benchmark", *argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("drill-gym benchmark: error: ")
    assert re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_runs_without_a_value_give_no_iqm_and_are_counted(tmp_path: Path) -> None:
    suite = load_suite(_tiny(tmp_path))
    rows = []
    for entry in ("proposed", "partial"):
        for scenario in suite.scenarios:
            for k, seed in enumerate(scenario.seeds):
                value = None if entry == "partial" and k == 0 else 1.0 + k
                rows.append(
                    {"suite": suite.label, "entry": entry, "scenario": scenario.id, "seed": seed,
                     "prone": scenario.prone, "diverged": entry == "proposed" and k == 1,
                     **dict.fromkeys(METRICS, value)}
                )  # fmt: skip
    scores = {(s["entry"], s["metric"]): s for s in score_suite(suite, rows, resamples=200)}
    partial, reference = scores[("partial", "iae")], scores[("proposed", "iae")]
    assert math.isnan(partial["iqm"]) and math.isnan(partial["score"])
    assert partial["missing"] == len(suite.scenarios) and partial["runs"] == 2 * len(
        suite.scenarios
    )
    assert reference["diverged"] == len(suite.scenarios) and reference["missing"] == 0
    assert reference["iqm"] == pytest.approx(1.5)


def test_a_user_controller_that_raises_is_one_line_naming_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = tmp_path / "fragile_loops.py"
    source.write_text(
        "class Fragile:\n"
        "    def reset(self): pass\n"
        "    def torque(self, measurement, reference_speed_rad_s, dt_s):\n"
        "        raise RuntimeError('out of coffee')\n"
    )
    suite = _tiny(tmp_path)
    code = main(["benchmark", f"{source}:Fragile", "--suites", str(suite), "--no-progress",
                 "--out", str(tmp_path / "out")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert (
        "fragile_loops.Fragile failed on tiny-v1 h01 seed 9001: RuntimeError: out of coffee" in err
    )


def test_without_scipy_the_command_stops_before_any_run(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "scipy" else real(name, *a)
    )
    code = main(["benchmark", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "pip install -e '.[bench]'" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_a_name_loads_the_latest_version_and_a_label_its_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import experiments.benchmark as benchmark

    _tiny(tmp_path)
    _tiny(tmp_path, version=2, episode_s=20.0)
    _tiny(tmp_path, version=10, episode_s=30.0)
    monkeypatch.setattr(benchmark, "SUITE_DIR", tmp_path)
    assert shipped_suites() == ["tiny-v1", "tiny-v2", "tiny-v10"]
    assert load_suite("tiny").label == "tiny-v10" and load_suite("tiny").episode_s == 30.0
    assert load_suite("tiny-v2").episode_s == 20.0


def test_the_command_line_is_the_spec() -> None:
    args = benchmark._parser().parse_args(
        ["proposed", "stiff_pi", "--suites", "deep", "deep", "--resamples", "200", "--no-plots"]
    )
    spec = spec_from_args(benchmark.BenchmarkSpec, args)
    assert spec == benchmark.BenchmarkSpec(
        policies=("proposed", "stiff_pi"), suites=("deep", "deep"), resamples=200, no_plots=True
    )
    assert spec.suite_names() == ["deep"] and spec.entry_names() == ["proposed", "stiff_pi"]
    every = benchmark.BenchmarkSpec()
    assert every.suite_names() == ["corners", "deep", "field", "heldout", "outside"]
    assert (
        "proposed" in every.entry_names() and "--policies" not in benchmark._parser().format_help()
    )


# ----------------------------------------------------------------------- training seeds
def _seed_models(folder: Path, seeds: Sequence[int], name: str = "residual_ppo") -> list[Path]:
    """Model folders ``folder/run_S/model`` (as sweep-train writes them): the shipped
    ``residual_ppo`` with its action weights scaled per seed and ``train_config.seed = S``."""
    from agents.policy import ResidualPolicy, load_policy

    shipped = load_policy(ROOT / "agents" / "models" / "residual_ppo")
    out = []
    for seed in seeds:
        factor = 1.0 + 0.5 * (seed - seeds[0])  # different models: different runs
        weights = {k: v * factor if "action" in k else v for k, v in shipped.weights.items()}
        config = {**shipped.metadata["train_config"], "seed": seed}
        model = ResidualPolicy(
            shipped.spec, weights, shipped.obs_norm, shipped.env_kwargs, name,
            {**shipped.metadata, "train_config": config}, env_id=shipped.env_id,
        )  # fmt: skip
        out.append(model.save(folder / f"run_{seed}" / "model"))
    return out


def test_a_stratum_of_one_training_seed_is_the_one_level_bootstrap() -> None:
    rng = np.random.default_rng(3)
    strata = [rng.normal(loc, 1.0, size=5) for loc in (10, 20, 15)]
    flat = iqm_interval(strata, resamples=500, seed=4)
    assert iqm_interval([s.reshape(1, -1) for s in strata], resamples=500, seed=4) == flat


def _hand_two_level(grids: list[np.ndarray], resamples: int, seed: int) -> tuple[float, float]:
    """The two-level stratified bootstrap written out: per scenario, its training seeds with
    replacement, then each drawn seed's reset seeds with replacement."""
    rng = np.random.default_rng(seed)
    stats = []
    for _ in range(resamples):
        drawn = []
        for grid in grids:
            for row in rng.integers(grid.shape[0], size=(grid.shape[0],)):
                drawn.append(rng.choice(grid[row], size=grid.shape[1], replace=True))
        pooled = np.sort(np.concatenate(drawn))
        cut = int(0.25 * pooled.size)
        stats.append(pooled[cut : pooled.size - cut].mean())
    return float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


def test_the_interval_over_training_seeds_matches_a_hand_two_level_bootstrap() -> None:
    rng = np.random.default_rng(11)
    # 4 scenarios x 5 training seeds x 3 reset seeds: a seed offset shared by its runs
    grids = [
        loc + rng.normal(0.0, 3.0, size=(5, 1)) + rng.normal(0.0, 0.3, size=(5, 3))
        for loc in (10.0, 20.0, 15.0, 30.0)
    ]
    point, low, high = iqm_interval(grids, resamples=4000, seed=1)
    assert point == pytest.approx(iqm(np.concatenate([g.ravel() for g in grids])))
    hand_low, hand_high = _hand_two_level(grids, 4000, 2)
    width = hand_high - hand_low
    assert low == pytest.approx(hand_low, abs=0.08 * width)
    assert high == pytest.approx(hand_high, abs=0.08 * width)


def test_the_interval_covers_the_spread_between_training_seeds() -> None:
    # Each training seed's runs agree closely (little reset-seed noise) and the seeds differ:
    # resampling the training seeds gives a wide interval; resampling the runs as if they
    # were independent (one training seed of 15 runs) a much narrower one.
    rng = np.random.default_rng(5)
    grids = [
        loc + rng.normal(0.0, 2.0, size=(5, 1)) + rng.normal(0.0, 0.05, size=(5, 3))
        for loc in (10.0, 20.0, 15.0)
    ]
    _, low, high = iqm_interval(grids, resamples=2000)
    _, flat_low, flat_high = iqm_interval([g.ravel() for g in grids], resamples=2000)
    assert high - low > 1.3 * (flat_high - flat_low)
    # identical training seeds: only the reset seeds move the IQM
    same = [np.tile(g[:1], (5, 1)) for g in grids]
    _, low, high = iqm_interval(same, resamples=2000)
    assert high - low < 0.5 * (flat_high - flat_low)
    # the scenarios stay strata: one always 0, one always 1, whatever the training seed
    assert iqm_interval([np.zeros((3, 2)), np.ones((3, 2))], resamples=200) == (0.5, 0.5, 0.5)


def test_score_suite_over_training_seeds(tmp_path: Path) -> None:
    suite = load_suite(_tiny(tmp_path))
    rows = []
    for scenario in suite.scenarios:
        for seed in scenario.seeds:
            head = {"suite": suite.label, "scenario": scenario.id, "seed": seed,
                    "prone": scenario.prone}  # fmt: skip
            rows.append({**head, "entry": "proposed", **dict.fromkeys(METRICS, 5.0)})
            for trained, value in ((1, 1.0), (2, 3.0), (3, 2.0)):
                rows.append(
                    {**head, "entry": "method", "training_seed": trained,
                     **dict.fromkeys(METRICS, value + 0.01 * (seed % 7))}
                )  # fmt: skip
    scores = {(s["entry"], s["metric"]): s for s in score_suite(suite, rows, resamples=300)}
    method = scores[("method", "iae")]
    assert method["training_seeds"] == 3 and "training_seeds" not in scores[("proposed", "iae")]
    assert method["runs"] == 3 * suite.runs
    assert method["ci_low"] < 1.9 and method["ci_high"] > 2.1  # the seeds' spread, 1 to 3
    table = training_seed_table(suite, rows)
    lines = table.splitlines()
    assert len(lines) == 2 + 3 and lines[2].startswith("| method | 1 | 1 |")
    assert lines[3].startswith("| method | 2 | 3 |") and lines[4].startswith("| method | 3 | 2 |")


def test_a_folder_of_training_seeds_is_one_method(tmp_path: Path) -> None:
    _seed_models(tmp_path / "sweep" / "runs", [4, 2, 3])
    (tmp_path / "sweep" / "runs" / "run_5").mkdir()  # a run that has not finished: no model/
    (tmp_path / "sweep" / "runs" / "run_5" / "config.json").write_text("{}")
    shutil.copytree(
        tmp_path / "sweep" / "runs" / "run_2" / "model", tmp_path / "sweep" / "best_model"
    )
    entry = make_entry(str(tmp_path / "sweep"))  # the sweep-train folder: its runs/
    assert entry.name == "residual_ppo" and entry.seed_count == 3
    assert [k for k, _ in entry.training_seeds] == [2, 3, 4]
    named = make_entry(f"seeds_x3={tmp_path / 'sweep' / 'runs'}")
    assert named.name == "seeds_x3" and named.seed_count == 3
    one = make_entry(f"only={tmp_path / 'sweep' / 'runs' / 'run_2' / 'model'}")
    assert one.name == "only" and one.seed_count == 1 and not one.training_seeds
    parts = merge_entries(
        [make_entry(f"m={tmp_path / 'sweep' / 'runs' / f'run_{k}'}") for k in (3, 2)]
    )
    assert len(parts) == 1 and [k for k, _ in parts[0].training_seeds] == [2, 3]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: [f"m={p / 'a' / 'run_1'}", f"m={p / 'b' / 'run_1'}"], "training seed 1 appears twice"),
        (lambda p: [f"m={p / 'a'}", f"m={ROOT / 'agents' / 'models' / 'field_agent'}"], "share their env"),
        (lambda p: [str(p / "empty")], "no model at|expected a model folder"),
    ],
    ids=["same-seed", "other-env", "no-models"],
)  # fmt: skip
def test_bad_training_seeds_are_an_error_naming_them(
    tmp_path: Path, make: Any, message: str
) -> None:
    _seed_models(tmp_path / "a", [1, 2])
    _seed_models(tmp_path / "b", [1])
    (tmp_path / "empty").mkdir()
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        merge_entries([make_entry(text) for text in make(tmp_path)])


def test_the_command_scores_a_method_over_its_training_seeds(tmp_path: Path) -> None:
    _seed_models(tmp_path / "sweep" / "runs", [1, 2])
    suite = _tiny(tmp_path)
    out = tmp_path / "out"
    code = main(["benchmark", f"seeds={tmp_path / 'sweep'}", "--suites", str(suite),
                 "--out", str(out), "--resamples", "200", "--no-progress", "--no-plots"])  # fmt: skip
    assert code == 0
    with (out / "runs.csv").open() as f:
        runs = list(csv.DictReader(f))
    assert list(runs[0])[:3] == ["suite", "entry", "training_seed"]
    mine = [r for r in runs if r["entry"] == "seeds"]
    assert len(mine) == 2 * 2 * 2 and {r["training_seed"] for r in mine} == {"1", "2"}
    assert {r["training_seed"] for r in runs if r["entry"] == "proposed"} == {""}
    assert len({r["iae"] for r in mine}) > 2  # the two models differ
    with (out / "scorecard.csv").open() as f:
        scores = {(r["entry"], r["metric"]): r for r in csv.DictReader(f)}
    assert scores[("seeds", "iae")]["training_seeds"] == "2"
    text = (out / "scorecard.md").read_text()
    assert "seeds (2 training seeds: 1, 2)" in text and "| seeds, 2 training seeds |" in text
    assert "| seeds | 1 |" in text and "| seeds | 2 |" in text
    assert "one training seed" not in text


# ------------------------------------------------------------------------------- the runner
def _tables(out: Path) -> dict[str, str]:
    """The CSV tables and the scorecard without its command line (it names the folder)."""
    tables = {p.name: p.read_text() for p in sorted(out.glob("*.csv"))}
    text = (out / "scorecard.md").read_text()
    tables["scorecard.md"] = "\n".join(
        line for line in text.splitlines() if not line.startswith("Command:")
    )
    return tables


def test_a_results_database_and_a_resume_give_the_serial_scorecard(tmp_path: Path) -> None:
    _seed_models(tmp_path / "sweep" / "runs", [1, 2])
    base = ["benchmark", "stiff_pi", f"seeds={tmp_path / 'sweep'}", "--suites",
            str(_tiny(tmp_path)), "--resamples", "200", "--no-progress", "--no-plots"]  # fmt: skip
    database = tmp_path / "b.sqlite"
    assert main([*base, "--out", str(tmp_path / "serial")]) == 0
    assert main([*base, "--out", str(tmp_path / "db"), "--results", str(database)]) == 0
    # a run lost from the database is run again on resume; the rest are read back
    with sqlite3.connect(database) as db:
        assert db.execute("SELECT COUNT(*) FROM results").fetchone() == ((1 + 2 + 1) * 2 * 2,)
        db.execute("DELETE FROM results WHERE item = (SELECT MAX(item) FROM results)")
    again = [*base, "--out", str(tmp_path / "again"), "--results", str(database), "--resume"]
    assert main([*again, "--task-size", "3"]) == 0
    serial = _tables(tmp_path / "serial")
    assert _tables(tmp_path / "db") == serial == _tables(tmp_path / "again")


def test_the_settings_hash_follows_the_suites_and_the_models(tmp_path: Path) -> None:
    models = _seed_models(tmp_path / "sweep" / "runs", [1, 2])
    suite = load_suite(_tiny(tmp_path))
    (tmp_path / "longer").mkdir()
    other_suite = load_suite(_tiny(tmp_path / "longer", episode_s=20.0))
    entries = (make_entry("proposed"), make_entry(str(models[0])))
    study = BenchmarkStudy((suite,), entries)
    hashes = {
        spec_hash("benchmark", s.spec())
        for s in (
            study,
            BenchmarkStudy((other_suite,), entries),
            BenchmarkStudy((suite,), (entries[0], make_entry(str(models[1])))),
            BenchmarkStudy((suite,), (entries[0], make_entry("stiff_pi"))),
        )
    }
    assert len(hashes) == 4
    same = BenchmarkStudy((suite,), entries, task_runs=1)
    assert spec_hash("benchmark", same.spec()) == spec_hash("benchmark", study.spec())
    assert len(study.items()) == len(set(study.items())) == 2 * 2 * 2


def test_a_user_class_cannot_run_on_ray(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    argv = ["benchmark", "examples/custom_controller.py:SpeedPI", "--suites",
            str(_tiny(tmp_path)), "--workers", "2", "--out", str(tmp_path / "out")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is your own class, registered in this process only" in err


def test_on_ray_the_scorecard_is_the_serial_one(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    base = ["benchmark", "stiff_pi", "agents/models/residual_ppo", "--suites",
            str(_tiny(tmp_path)), "--resamples", "200", "--no-progress", "--no-plots"]  # fmt: skip
    assert main([*base, "--out", str(tmp_path / "serial")]) == 0
    assert main([*base, "--out", str(tmp_path / "ray"), "--workers", "2"]) == 0
    assert _tables(tmp_path / "ray") == _tables(tmp_path / "serial")


def test_the_profiles_label_a_log_axis_at_its_decades_only() -> None:
    """Values over 1.5 decades (a log axis) get tick labels that do not overlap: matplotlib
    labels the minor ticks of so short a log axis, and they run into each other."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from experiments.plots import text_problems

    suite = load_suite("outside-v1")
    rng = np.random.default_rng(0)
    rows = [
        {
            "suite": suite.label,
            "entry": entry,
            "scenario": scenario.id,
            **{metric: float(rng.uniform(2e3, 6e4)) for metric in METRICS},
        }
        for entry in ("a", "b")
        for scenario in suite.scenarios
    ]
    fig = benchmark.profiles_figure([suite], rows)
    FigureCanvasAgg(fig)
    assert text_problems(fig) == []
