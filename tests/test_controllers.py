"""A user's own controller on the command line (:mod:`experiments.controllers`):
``MODULE:CLASS`` and ``PATH.py:CLASS`` in ``compare``, ``map`` and ``evaluate``, and the
one-line errors of a missing file, module or class and of a class that is no controller.

The commands run as a user types them (``python -m experiments.cli ...`` from the project
root, short runs); the error cases run in-process (each is one line and exit code 2).
"""

from __future__ import annotations

import csv
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from experiments.cli import main
from experiments.controllers import load_controller, resolve_controller_name

ROOT = Path(__file__).resolve().parents[1]
FILE_SPEC = "examples/custom_controller.py:SpeedPI"
MODULE_SPEC = "examples.compiled_controller:CompiledSpeedPI"


@pytest.fixture(autouse=True)
def _own_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """The users' classes a test registers stay in that test (the registry is per process)."""
    import baselines  # noqa: F401  (the built-in ones first, in their order, before the copy)
    import drill_env.control as control
    import experiments.controllers as controllers

    monkeypatch.setattr(control, "_FACTORIES", dict(control._FACTORIES))
    monkeypatch.setattr(controllers, "_LOADED", {})
    monkeypatch.setattr(controllers, "_CODE", {})


def command(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "experiments.cli", *argv],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )


def test_compare_runs_a_file_and_a_module_controller_beside_a_registered_one(
    tmp_path: Path,
) -> None:
    done = command(
        "compare", "--controllers", "stiff_pi", FILE_SPEC, MODULE_SPEC,
        "--duration", "3", "--conditions", "nominal", "--noise", "0",
        "--no-agent", "--no-plots", "--no-progress", "--out", str(tmp_path),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    with (tmp_path / "compare.csv").open() as f:
        rows = {r["controller"]: r for r in csv.DictReader(f)}
    assert set(rows) == {
        "stiff_pi",
        "custom_controller.SpeedPI",
        "compiled_controller.CompiledSpeedPI",
    }
    # The Python class and its compiled twin are the same law: the same run.
    python, compiled = (
        rows["custom_controller.SpeedPI"],
        rows["compiled_controller.CompiledSpeedPI"],
    )
    for key in ("iae", "rmsd_nm", "chattering_nm_per_s"):
        assert float(python[key]) == pytest.approx(float(compiled[key]), rel=1e-9), key
    assert float(python["rmsd_nm"]) != pytest.approx(float(rows["stiff_pi"]["rmsd_nm"]), rel=1e-3)


def test_map_and_evaluate_take_a_user_controller(tmp_path: Path) -> None:
    done = command(
        "map", "--controllers", FILE_SPEC, "--wob-n", "1", "--speed-n", "2",
        "--duration", "2", "--window", "1", "--no-plots", "--no-progress",
        "--out", str(tmp_path / "map"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "custom_controller.SpeedPI" in done.stdout
    assert list((tmp_path / "map").glob("*custom_controller.SpeedPI*.csv"))
    done = command(
        "evaluate", "agents/models/residual_ppo", "--controllers", MODULE_SPEC,
        "--scenarios", "h14", "--no-plots", "--no-progress", "--out", str(tmp_path / "ev"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    with (tmp_path / "ev" / "heldout.csv").open() as f:
        labels = {r["controller"] for r in csv.DictReader(f)}
    assert "compiled_controller.CompiledSpeedPI" in labels


PI_FILE = """
class Loop:
    kp = {kp}

    def reset(self):
        self.integral = 0.0

    def torque(self, measurement, reference_speed_rad_s, dt_s):
        error = reference_speed_rad_s - measurement.surface_top_drive_speed_rad_s
        self.integral += error * dt_s
        return 13000.0 + self.kp * error + 500.0 * self.integral
"""


def test_an_edited_user_class_is_run_again_not_read_from_the_results(tmp_path: Path) -> None:
    """The results database keys a user's class by its name and its file's code: after an
    edit, ``--resume`` runs the new class instead of giving it the old class's rows."""
    loop = tmp_path / "my_loop.py"
    database = tmp_path / "runs.sqlite"

    def compare(out: str, *extra: str) -> dict[str, str]:
        done = command(
            "compare", "--controllers", f"{loop}:Loop", "--duration", "2",
            "--conditions", "nominal", "--noise", "0", "--no-agent", "--no-plots",
            "--no-progress", "--results", str(database), "--out", str(tmp_path / out), *extra,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        with (tmp_path / out / "compare.csv").open() as f:
            return {r["controller"]: r["rmsd_nm"] for r in csv.DictReader(f)}

    loop.write_text(PI_FILE.format(kp=2000.0))
    first = compare("first")
    again = compare("again", "--resume")  # same code: read back, the same numbers
    loop.write_text(PI_FILE.format(kp=6000.0))
    edited = compare("edited", "--resume")
    assert first == again
    assert edited["my_loop.Loop"] != first["my_loop.Loop"]


def test_user_code_enters_the_settings_only_where_a_user_class_is_named(tmp_path: Path) -> None:
    from experiments.controllers import user_code_fingerprints

    (tmp_path / "loop_a.py").write_text(PI_FILE.format(kp=1.0))
    name = load_controller(f"{tmp_path / 'loop_a.py'}:Loop")
    code = user_code_fingerprints({"jobs": [[f"{name} (surface)", "x"], ["proposed"]]})
    assert list(code) == [name] and len(code[name]) == 64
    assert user_code_fingerprints({"jobs": [["proposed", name + "x"]], "n": 3}) == {}


def test_help_says_how_to_name_your_own_class_and_the_guide_how_to_compile_it(
    capsys: pytest.CaptureFixture[str],
) -> None:
    for name in ("compare", "map", "evaluate", "benchmark"):
        assert main([name, "--help"]) == 0
        out = " ".join(capsys.readouterr().out.split())
        assert "MODULE:CLASS" in out and "PATH.py:CLASS" in out, name
        assert "runs its code" in out and "only code you trust" in out, name
    guide = (ROOT / "docs" / "controllers.md").read_text()
    assert "compiled_law(" in guide and "examples/compiled_controller.py" in guide


BAD_CLASSES = """
class NoTorque:
    def reset(self): pass

class WrongTorque:
    def reset(self): pass
    def torque(self, measurement): return 0.0

class NeedsGains:
    def __init__(self, kp): self.kp = kp
    def reset(self): pass
    def torque(self, measurement, reference_speed_rad_s, dt_s): return 0.0

NOT_A_CLASS = 3
"""


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("no/such/file.py:X", "no Python file 'no/such/file.py'"),
        ("no_such_module_xyz:X", "no module named 'no_such_module_xyz'"),
        ("examples/custom_controller.py:Missing", "has no 'Missing'"),
        ("{bad}:NoTorque", r"has no torque\(\)"),
        ("{bad}:WrongTorque", r"does not take \(measurement, reference_speed_rad_s, dt_s\)"),
        ("{bad}:NeedsGains", r"NeedsGains\(\) failed: TypeError.*give every parameter a default"),
        ("{bad}:NOT_A_CLASS", "is not a class"),
        ("{broken}:X", "importing .* failed: SyntaxError"),
        ("examples/custom_controller.py:1x", "is not a Python class name"),
        ("nonsense", "unknown controller 'nonsense'.*MODULE:CLASS or PATH.py:CLASS"),
    ],
    ids=[
        "missing-file", "missing-module", "missing-class", "no-torque", "wrong-torque",
        "needs-arguments", "not-a-class", "syntax-error", "bad-class-name", "unknown-name",
    ],
)  # fmt: skip
@pytest.mark.parametrize("subcommand", ["compare", "map", "evaluate"])
def test_a_bad_user_controller_is_one_line_and_exit_code_2(
    subcommand: str,
    spec: str,
    message: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bad = tmp_path / "bad_loops.py"
    bad.write_text(BAD_CLASSES)
    broken = tmp_path / "broken_loops.py"
    broken.write_text("def oops(:\n")
    spec = spec.format(bad=bad, broken=broken)
    code = main([subcommand, "--controllers", spec, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"drill-gym {subcommand}: error: argument --controllers: ")
    assert re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_a_user_class_is_registered_once_under_a_short_name(tmp_path: Path) -> None:
    source = tmp_path / "my_loops.py"
    source.write_text(
        "class Hold:\n"
        "    def reset(self): pass\n"
        "    def torque(self, measurement, reference_speed_rad_s, dt_s): return 1.0e4\n"
    )
    name = load_controller(f"{source}:Hold")
    assert name == "my_loops.Hold"
    assert load_controller(f"{source}:Hold") == name  # the same spec: no second import
    assert resolve_controller_name(name) == name
    assert resolve_controller_name("proposed") == "proposed"
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "my_loops.py").write_text(source.read_text())
    with pytest.raises(ValueError, match="'my_loops.Hold' is already taken"):
        load_controller(f"{other / 'my_loops.py'}:Hold")


def test_a_user_class_does_not_run_on_ray(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["compare", "--controllers", FILE_SPEC, "--workers", "2", "--no-agent"])
    err = capsys.readouterr().err
    assert code == 2
    assert "registered in this process only" in err and err.count("\n") == 1
