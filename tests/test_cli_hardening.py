"""What comes from outside cannot run code, write outside ``--out`` or rank a broken controller
first: a suite file names only registered controllers, a link inside the output folder is
refused before any run, a controller's NaN or infinite torque ends its run as diverged with
the reason and ranks last, and a controller that returns anything but a number is one line on
standard error with exit code 2."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from drill_env.evaluation import ZeroAction, episode_metrics, rollout, termination_note
from experiments.benchmark import SUITE_DIR, load_suite, score_suite
from experiments.cli import main as cli_main
from experiments.compare import ranked_summary
from experiments.evaluate import goal_report, summarize
from experiments.evaluate import write_figures as write_heldout_figures
from experiments.paths import inside_output, output_file, output_path

SHORT = ["--duration-s", "1", "--conditions", "nominal", "--noise", "0", "--no-agent",
         "--no-progress"]  # fmt: skip

LOOPS = """\
import math

import numpy as np


class Loop:
    value = 0.0

    def reset(self):
        pass

    def torque(self, measurement, reference_speed_rad_s, dt_s):
        return self.value


class NotANumber(Loop):
    value = math.nan


class MinusInfinity(Loop):
    value = -math.inf


class Words(Loop):
    value = "lots"


class Three(Loop):
    def torque(self, measurement, reference_speed_rad_s, dt_s):
        return np.zeros(3)
"""

PAYLOAD = """\
from pathlib import Path

Path({marker!r}).write_text("ran")


class Evil:
    def reset(self):
        pass

    def torque(self, measurement, reference_speed_rad_s, dt_s):
        return 0.0
"""


@pytest.fixture(autouse=True)
def _own_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """The users' classes a test registers stay in that test (the registry is per process)."""
    import baselines  # noqa: F401  (the built-in ones first, in their order, before the copy)
    import drill_env.control as control
    import experiments.controllers as controllers

    monkeypatch.setattr(control, "_FACTORIES", dict(control._FACTORIES))
    monkeypatch.setattr(controllers, "_LOADED", {})


@pytest.fixture
def loops(tmp_path: Path) -> Path:
    path = tmp_path / "odd_loops.py"
    path.write_text(LOOPS)
    return path


def _one_error_line(err: str, prog: str) -> None:
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"drill-gym {prog}: error: "), err


# ------------------------------------------------------------ a suite names no code to run
def _suite(tmp_path: Path, reference: str) -> Path:
    data = json.loads((SUITE_DIR / "heldout-v1.json").read_text())
    data.update(name="tiny", episode_s=2.0, reference=reference)
    data["scenarios"] = [dict(s, seeds=s["seeds"][:2]) for s in data["scenarios"][:1]]
    path = tmp_path / "tiny-v1.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("form", ["file", "module"])
def test_a_suite_whose_reference_names_code_is_refused_without_running_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], form: str
) -> None:
    marker = tmp_path / "ran.txt"
    (tmp_path / "evil_loops.py").write_text(PAYLOAD.format(marker=str(marker)))
    monkeypatch.chdir(tmp_path)  # the module form is importable from the current folder
    monkeypatch.syspath_prepend(str(tmp_path))
    reference = f"{tmp_path / 'evil_loops.py'}:Evil" if form == "file" else "evil_loops:Evil"
    suite = _suite(tmp_path, reference)
    with pytest.raises(ValueError, match=r"field reference = .*allowed a registered controller"):
        load_suite(suite)
    code = cli_main(["benchmark", "stiff_pi", "--suites", str(suite), "--resamples", "100",
                     "--no-progress", "--no-plots", "--out", str(tmp_path / "out")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    _one_error_line(err, "benchmark")
    assert "field reference = " in err and "proposed" in err and "stiff_pi" in err
    assert not marker.exists()
    assert not (tmp_path / "out").exists()


def test_a_suite_may_name_a_registered_reference(tmp_path: Path) -> None:
    assert load_suite(_suite(tmp_path, "stiff_pi")).reference == "stiff_pi"


# ---------------------------------------------------------------- nothing outside --out
def test_a_link_inside_out_is_refused_before_any_run_and_nothing_lands_in_its_target(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / "figures").symlink_to(elsewhere, target_is_directory=True)
    code = cli_main(["compare", "--controllers", "csmc", *SHORT, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    _one_error_line(err, "compare")
    assert "outside the output folder" in err and "figures" in err
    assert list(elsewhere.iterdir()) == []
    assert sorted(p.name for p in out.iterdir()) == ["figures"]  # no run was made


def test_every_figure_writer_checks_the_output_folder(tmp_path: Path) -> None:
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / "figures").symlink_to(elsewhere, target_is_directory=True)
    with pytest.raises(ValueError, match="outside the output folder"):
        output_path(out, "figures", "bars.png")
    with pytest.raises(ValueError, match="outside the output folder"):
        inside_output(out, out / "figures" / "bars.png")
    with pytest.raises(ValueError, match="outside the output folder"):
        write_heldout_figures([], {}, [], out / "figures", root=out)
    from experiments.compare import write_figures

    with pytest.raises(ValueError, match="outside the output folder"):
        write_figures([], {}, out / "figures", out=out)
    with pytest.raises(ValueError, match="outside the output folder"):
        output_file(out, "figures", "coupled_stability_map.png")  # coupled, realism, waves
    assert inside_output(out, out / "a" / "b.png") == out / "a" / "b.png"
    assert output_file(out, "a", "b.png") == out / "a" / "b.png"
    assert list(elsewhere.iterdir()) == []
    (out / "loop").symlink_to(out / "loop")  # a loop of links: refused, not a traceback
    with pytest.raises(ValueError, match="cannot be resolved"):
        output_path(out, "loop", "bars.png")


# ----------------------------------------------------- a non-finite torque ranks last
def test_a_nan_or_infinite_torque_ends_the_run_as_diverged_and_ranks_last(
    tmp_path: Path, loops: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    code = cli_main(["compare", "--controllers", f"{loops}:NotANumber", f"{loops}:MinusInfinity",
                     "csmc", *SHORT, "--no-plots", "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0
    rows = {r["controller"]: r for r in json.loads((out / "compare.json").read_text())}
    assert rows["csmc"]["diverged"] is False and rows["csmc"]["note"] == ""
    for name, value in (("odd_loops.NotANumber", "nan"), ("odd_loops.MinusInfinity", "-inf")):
        assert rows[name]["diverged"] is True
        assert f"returned {value} N m" in rows[name]["note"]
    ranks = [
        line.split("|")[2].strip() for line in printed.splitlines() if re.match(r"\| \d", line)
    ]
    assert ranks[0] == "csmc"
    assert "Diverged runs (2)" in printed and "returned nan N m" in printed
    summary = ranked_summary(list(rows.values()))
    assert summary[0]["label"] == "csmc" and summary[0]["diverged"] == 0


def test_a_compiled_laws_non_finite_torque_is_a_diverged_run() -> None:
    from numba import cfunc

    from drill_env.control import LAW_SIGNATURE, CompiledLaw

    @cfunc(LAW_SIGNATURE)
    def infinite_law(params_ptr, state_ptr, measurement_ptr, reference_rad_s, dt_s):
        return math.inf

    class Infinite:
        def reset(self) -> None:
            pass

        def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
            return math.inf

        def compiled_law(self, model: Any = None, torque_limits: Any = None) -> CompiledLaw:
            return CompiledLaw(infinite_law, np.zeros(1), np.zeros(1))

    env = gym.make("DrillString-v0", base_controller=Infinite(), episode_s=0.2,
                   control_dt_s=0.1, randomize=False)  # fmt: skip
    trace = rollout(env, ZeroAction(), seed=0)
    env.close()
    assert episode_metrics(trace)["diverged"]
    assert "non-finite torque (inf N m)" in termination_note(trace)


def _runs(suite: Any, entry: str, value: float, diverged: bool) -> list[dict[str, Any]]:
    from experiments.benchmark import METRICS

    return [
        {"suite": suite.label, "entry": entry, "scenario": s.id, "seed": seed,
         "prone": s.prone, "diverged": diverged, **dict.fromkeys(METRICS, value + k)}
        for s in suite.scenarios for k, seed in enumerate(s.seeds)
    ]  # fmt: skip


def test_a_diverged_entry_is_never_the_best_nor_scored(tmp_path: Path) -> None:
    suite = load_suite(_suite(tmp_path, "proposed"))
    rows = _runs(suite, "proposed", 10.0, False) + _runs(suite, "stiff_pi", 5.0, False)
    rows += _runs(suite, "broken", 0.0, True)
    scores = {(s["entry"], s["metric"]): s for s in score_suite(suite, rows, resamples=100)}
    assert scores[("broken", "iae")]["best"] == "stiff_pi"
    assert scores[("stiff_pi", "iae")]["score"] == pytest.approx(1.0)
    assert math.isnan(scores[("broken", "iae")]["score"])
    assert scores[("broken", "iae")]["diverged"] == 2
    from experiments.benchmark import suite_table

    lines = [line for line in suite_table(suite, list(scores.values())).splitlines() if "|" in line]
    assert [line.split("|")[1].strip() for line in lines[2:]] == ["stiff_pi", "proposed", "broken"]


def _row(label: str, iae: float, diverged: bool = False) -> dict[str, Any]:
    metrics = dict.fromkeys(("ise", "rmse", "overshoot_pct", "stuck_fraction"), 1.0)
    return {"scenario": "a", "controller": label, "prone": True, "iae": iae, "rmsd_nm": 10.0,
            "stick_slip_severity": 0.5, "settling_time_s": None, "diverged": diverged,
            "chattering_nm_per_s": 1.0, "note": "returned nan N m" if diverged else "",
            **metrics}  # fmt: skip


def test_a_diverged_controller_never_sets_the_bar_and_a_diverged_agent_misses_the_goal() -> None:
    rows = [_row("proposed", 100), _row("broken", 0, diverged=True), _row("agent", 60)]
    summary = summarize(rows, agents=["agent"])
    assert summary["means"]["broken"]["diverged"] == 1  # kept, not left out as not run
    assert summary["goal"]["agent"]["best_engineered_iae"] == 100
    assert "IAE below every engineered controller's" not in summary["goal"]["agent"]["missed"]
    rows = [_row("proposed", 100), _row("agent", 60, diverged=True)]
    summary = summarize(rows, agents=["agent"])
    assert "no diverged run" in summary["goal"]["agent"]["missed"]
    assert "1 diverged runs (allowed none)" in goal_report(summary, ["agent"])


# --------------------------------------------------- a torque that is not a number
@pytest.mark.parametrize(
    ("name", "shown"), [("Words", "'lots' (str)"), ("Three", "array([0., 0., 0.]) (ndarray)")]
)
def test_a_controller_returning_no_number_is_one_line_naming_it(
    tmp_path: Path, loops: Path, capsys: pytest.CaptureFixture[str], name: str, shown: str
) -> None:
    code = cli_main(["compare", "--controllers", f"{loops}:{name}", *SHORT, "--no-plots",
                     "--out", str(tmp_path / "out")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    _one_error_line(err, "compare")
    assert f"controller odd_loops.{name} failed on nominal" in err
    assert f"returned {shown}" in err
