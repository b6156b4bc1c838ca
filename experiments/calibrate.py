"""``drill-gym calibrate LOG --window A:B --out DIR`` and ``drill-gym replay PLANT LOG --window
C:D --out DIR``: from a rig's measured log to a calibrated plant, and back to the log
(docs/calibration.md).

``calibrate`` reads and checks the log, reports its defects, fits every friction family of
:mod:`drill_env.bit_model` on the window, keeps the one of lowest BIC, and writes
``DIR/plant.json`` (:mod:`drill_env.calibrated_plant`), ``DIR/report.md`` and the figures
``fit.png`` (measured against simulated speed and torque, residuals), ``loop.png`` (the
torque-speed loop) and ``uncertainty.png`` (relative standard deviations). ``replay`` drives a
plant with the log's measured top-drive speed on a window and writes ``DIR/replay.csv``,
``DIR/features.csv``, ``DIR/replay.md`` and ``DIR/replay.png``.

Only files of these names are written, only inside ``--out``; an existing ``--out`` that is
not a directory is refused before any work.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final, NamedTuple

import numpy as np
import numpy.typing as npt

from drill_env.bit_model import FAMILIES
from drill_env.calibrated_plant import MODEL_PARAMETERS, PLANT_FORMAT, check_parameter, load_plant
from drill_env.files import replacing, write_text
from drill_env.measured_log import MeasuredLog, find_defects, read_log
from drill_env.validation import printable
from drill_env.validation import shown as shown_value
from experiments.arguments import ArgumentParser
from experiments.calibration_fit import (
    FEATURE_KEYS,
    WEAKLY_PINNED,
    FitResult,
    calibrate,
    feature_errors,
    features,
    simulate_free,
    simulate_plant,
    stuck_threshold,
)
from experiments.spec_cli import option, spec_from_args, spec_parser

__all__ = [
    "CalibrateSpec",
    "ReplaySpec",
    "Window",
    "main",
    "replay_main",
    "replay_parser",
    "window_type",
]

CALIBRATE_FILES = ("plant.json", "report.md", "fit.png", "loop.png", "uncertainty.png")
"""The files ``calibrate`` writes into ``--out``."""
REPLAY_FILES = ("replay.csv", "features.csv", "replay.md", "replay.png")
"""The files ``replay`` writes into ``--out``."""


class Window(NamedTuple):
    """A time window of a log, ``--window A:B``."""

    start_s: float
    """start (s)"""
    end_s: float
    """end (s), after the start"""


def window_type(text: str) -> Window:
    """Parse ``A:B`` (seconds, ``A < B``) for ``--window``."""
    parts = text.split(":")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{shown_value(text)} is not A:B (start:end in s)")
    try:
        a, b = float(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{shown_value(text)} is not A:B with numbers (s)"
        ) from None
    if not (math.isfinite(a) and math.isfinite(b) and a < b):
        raise argparse.ArgumentTypeError(f"{shown_value(text)}: allowed finite A < B (s)")
    return Window(a, b)


def fix_type(text: str) -> tuple[str, float]:
    """Parse ``NAME=VALUE`` for ``--fix``: a model parameter and a value within its range
    (:data:`drill_env.calibrated_plant.PARAMETER_RANGES`)."""
    name, _, value = text.partition("=")
    if name not in MODEL_PARAMETERS:
        raise argparse.ArgumentTypeError(
            f"unknown parameter {shown_value(name)}: allowed {', '.join(MODEL_PARAMETERS)}"
        )
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{shown_value(text)} is not NAME=VALUE with a number"
        ) from None
    try:
        return name, check_parameter(name, number)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def check_simulation(
    what: str, window: MeasuredLog, arrays: dict[str, npt.NDArray[np.float64]]
) -> None:
    """``ValueError`` when a simulation of ``what`` on ``window`` diverged (the simulator
    returns NaN once a speed or twist leaves its bounds): the first column and time it did,
    instead of a table of NaN."""
    for name, values in arrays.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            at = float(window.time_s[int(bad[0])])
            raise ValueError(
                f"the simulation of {what} diverged: {name} is not finite from t = {at:g} s "
                f"({bad.size} of {values.size} samples); the plant's parameters do not fit "
                "this log (a plant too stiff or too light for its sample period)"
            )


def _head(path: Path) -> str:
    try:
        with path.open(encoding="utf-8") as f:
            return f.read(300)
    except (OSError, UnicodeDecodeError):
        return ""


def prepare_out(out: Path, names: Sequence[str], signature: tuple[str, str]) -> None:
    """Check ``out`` (made later, by the first write), refusing an existing non-directory;
    files of ``names`` already there are replaced only when they are a previous run's: regular
    files, and the run's main file ``signature[0]`` holds ``signature[1]`` in its first 300
    characters (otherwise they are someone else's)."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {str(out)!r} exists and is not a directory")
    present = [out / n for n in names if (out / n).exists() or (out / n).is_symlink()]
    for target in present:
        if target.is_symlink() or not target.is_file():
            raise ValueError(f"--out: {str(target)!r} exists and is not a regular file")
    main_file, start = signature
    if present and start not in _head(out / main_file):
        raise ValueError(
            f"--out: {str(present[0])!r} exists and is not from a previous run of this command "
            "(not overwritten): choose another directory"
        )
    # The folder is made by the first write, once every input has been read and checked.


def _format(value: float | None, digits: int = 4) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:.{digits}g}"


def _fit_figure(
    window: MeasuredLog, speed: npt.NDArray[np.float64], torque: npt.NDArray[np.float64], title: str
) -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = window.time_s
    bit = window.column("bit_speed_rad_s")
    tq = window.column("bit_torque_nm")
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True, layout="constrained")
    axes[0].plot(t, bit, color="0.6", lw=0.8, label="measured")
    axes[0].plot(t, speed, color="C0", lw=1.0, label="simulated")
    axes[0].set_ylabel("bit speed (rad/s)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].plot(t, tq, color="0.6", lw=0.8, label="measured")
    axes[1].plot(t, torque, color="C1", lw=1.0, label="simulated")
    axes[1].set_ylabel("torque on bit (N m)")
    axes[1].legend(loc="upper right", fontsize=8)
    axes[2].plot(t, speed - bit, color="C0", lw=0.6)
    axes[2].set_ylabel("speed residual (rad/s)")
    axes[3].plot(t, torque - tq, color="C1", lw=0.6)
    axes[3].set_ylabel("torque residual (N m)")
    axes[3].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    return fig


def _loop_figure(
    window: MeasuredLog, speed: npt.NDArray[np.float64], torque: npt.NDArray[np.float64], title: str
) -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5), layout="constrained")
    ax.plot(window.column("bit_speed_rad_s"), window.column("bit_torque_nm"), color="0.6",
            lw=0.5, label="measured")  # fmt: skip
    ax.plot(speed, torque, color="C3", lw=1.0, label="simulated")
    ax.set_xlabel("bit speed (rad/s)")
    ax.set_ylabel("torque on bit (N m)")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title, fontsize=10)
    return fig


def _uncertainty_figure(result: FitResult) -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plant = result.plant
    names = list(plant.parameters)
    values = [plant.parameters[n].relative_std for n in names]
    fig, ax = plt.subplots(figsize=(7, 3.8), layout="constrained")
    for i, (name, rel) in enumerate(zip(names, values, strict=False)):
        p = plant.parameters[name]
        if p.identified and rel is not None and math.isfinite(rel):
            ax.barh(i, max(rel * 100, 1e-4), color="C0")
        else:
            ax.barh(i, 100, color="0.85", hatch="//")
            ax.text(1e-3, i, "not identified: fixed", va="center", fontsize=8)
    ax.set_yticks(range(len(names)), names)
    ax.set_xscale("log")
    ax.set_xlim(1e-3, 200)
    ax.axvline(25, color="C3", lw=0.8, ls="--")
    ax.set_xlabel("relative standard deviation (%); dashed: identifiability limit")
    ax.set_title(f"parameter uncertainty, family {plant.family}", fontsize=10)
    return fig


def _save(fig: Any, path: Path) -> None:
    import matplotlib.pyplot as plt

    with replacing(path, "wb") as f:
        fig.savefig(f, dpi=110, format="png")
    plt.close(fig)


def _defect_lines(defects: Sequence[Any], start: float, end: float) -> list[str]:
    lines = []
    for d in defects:
        inside = " (inside the window)" if d.overlaps(start, end) else ""
        lines.append(
            f"| {d.kind} | {d.column} | {d.start_s:.6g} to {d.end_s:.6g} | {d.rows[0]}-{d.rows[1]} "
            f"| {d.detail}{inside} |"
        )
    return lines


def _report(
    result: FitResult, log: MeasuredLog, window_s: tuple[float, float], command: str
) -> str:
    plant = result.plant
    lines = [
        "# Calibration report",
        "",
        f"Command: `{command}`",
        "",
        f"Log: {log.source} ({log.time_s.size} samples, {log.time_s[0]:g} to {log.time_s[-1]:g} s, "
        f"median sample period {log.sample_period_s:.4g} s). Window: {window_s[0]:g} to "
        f"{window_s[1]:g} s. Wall time of the fit: {result.wall_s:.1f} s.",
        "",
        "## Defects of the log",
        "",
    ]
    all_defects = find_defects(log)
    if all_defects:
        lines += ["| kind | column | time (s) | rows | seen |", "|---|---|---|---|---|"]
        lines += _defect_lines(all_defects, *window_s)
    else:
        lines.append("None found.")
    lines += [
        "",
        f"The data are not changed. {result.excluded_samples} residuals of the window (spikes and "
        "flat lines of the bit speed and the torque on bit) are left out of the fit; a gap "
        "inside the window is bridged by the linear interpolation of the top-drive speed.",
        "",
        "## Friction family",
        "",
        "| family | free parameters | normalised RMS residual | BIC |",
        "|---|---|---|---|",
    ]
    for name, info in plant.fit["families"].items():
        chosen = " (chosen)" if name == plant.family else ""
        lines.append(
            f"| {name}{chosen} | {info['free_parameters']} | {_format(info['normalised_rms'])} | "
            f"{info['bic']:.1f} |"
        )
    n_eff = next(iter(plant.fit["families"].values()))["n_effective"]
    lines += [
        "",
        f"BIC = n_eff ln(RSS/n) + k ln(n_eff), with n_eff = {n_eff:.0f} the effective number "
        "of independent residuals (from their autocorrelation). Lowest wins.",
        "",
        "## Parameters",
        "",
        "| parameter | value | unit | relative std | 95 % interval | status |",
        "|---|---|---|---|---|---|",
    ]
    for name, p in plant.parameters.items():
        if p.identified:
            interval = (
                "-" if p.interval_95 is None
                else f"{p.interval_95[0]:.4g} to {p.interval_95[1]:.4g}"
            )  # fmt: skip
            status = "fitted, weakly pinned" if WEAKLY_PINNED in p.note else "fitted"
            lines.append(
                f"| {name} | {p.value:.6g} | {p.unit} | {_format(p.relative_std, 2)} | "
                f"{interval} | {status} |"
            )
        else:
            lines.append(f"| {name} | (held at {p.value:.4g}) | {p.unit} | - | - | {p.note} |")
    boot = result.bootstrap
    how = boot.description() if boot is not None else "the Laplace approximation"
    lines += [
        "",
        f"Initial twist of the window: {plant.initial_twist_rad:.6g} rad (fitted, a nuisance "
        "parameter). Which parameters are identified is screened with the Laplace "
        "approximation (the inverse Gauss-Newton Hessian at the optimum, scaled by the "
        "residual variance and inflated by n / n_eff): a parameter above "
        f"{plant.fit['max_relative_std']:.0%} is reported as not identifiable, held fixed, "
        f"and the rest refitted. The relative standard deviations and intervals come from {how}; "
        "they hold for the model family and the held values, and do not contain the error of "
        "the model's form (docs/calibration.md).",
        "",
        "## Top drive (free-running mode)",
        "",
        *_top_drive_lines(result),
        "",
        "![fit](fit.png)",
        "",
        "![loop](loop.png)",
        "",
        "![uncertainty](uncertainty.png)",
        "",
    ]
    return "\n".join(lines)


def _top_drive_lines(result: FitResult) -> list[str]:
    top = result.top_drive
    if top is None or top.values is None:
        reason = top.reason if top is not None else "not identified"
        return [f"Not identified: {reason}. `drill-gym replay --free-running` needs it."]
    v = top.values
    return [
        f"Identified from the top speed and the surface torque: inertia "
        f"{v['inertia_kg_m2']:.4g} kg m^2 (momentum balance of top drive and bit, R^2 "
        f"{top.balance_r2:.3f}); PI speed loop with gains {v['speed_gain_nm_s_rad']:.4g} N m s/rad "
        f"and {v['integral_gain_nm_rad']:.4g} N m/rad around {v['reference_speed_rad_s']:.4g} "
        f"rad/s (R^2 {top.loop_r2:.3f}). `drill-gym replay --free-running` runs the plant with "
        "this top drive instead of the measured top speed.",
        *_string_lines(result),
    ]


def _string_lines(result: FitResult) -> list[str]:
    string = result.string
    if string is None or not string.models:
        return []
    lines = [
        "",
        "The string above the bit side, fitted to the top speed and surface torque (the "
        "identified speed loop, driven by the measured bit speed; Laplace relative std in "
        "brackets):",
        "",
        "| model | normalised RMS | BIC | parameters |",
        "|---|---|---|---|",
    ]
    for model in string.models.values():
        parts = []
        for name, value in model.values.items():
            if name in model.held:
                parts.append(f"{name} held at 0 (not identifiable)")
            else:
                parts.append(f"{name} {value:.4g} ({_format(model.relative_std.get(name), 2)})")
        lines.append(f"| {model.name} | {model.rms:.3f} | {model.bic:.1f} | {'; '.join(parts)} |")
    chosen = (
        "the pipe: free running uses its top drive, pipe and spring"
        if string.chosen == "pipe"
        else f"one inertia ({string.reason}): free running uses the top drive above"
    )
    lines += ["", f"Chosen: {chosen}."]
    if string.bridged_spikes:
        lines += [
            "",
            f"{string.bridged_spikes} spike sample(s) of the bit speed, which drives this fit "
            "through its integral, are bridged by the linear interpolation of their neighbours "
            "here (the bit side's fit leaves them out of its residual instead).",
        ]
    return lines


LOG_HELP: Final = "the measured log (.csv, or .parquet with pyarrow)"
"""Help of the LOG argument of ``calibrate`` and ``replay``."""
OUT_HELP: Final = "output directory, made if missing (required)"
"""Help of ``--out`` of ``calibrate`` and ``replay``."""


@dataclasses.dataclass(frozen=True)
class CalibrateSpec:
    """Settings of ``drill-gym calibrate``; its arguments are generated from these fields."""

    log: str | None = dataclasses.field(
        default=None, metadata=option(positional=True, metavar="LOG", help=LOG_HELP)
    )
    """the measured log (required)"""
    window: Window | None = dataclasses.field(
        default=None, metadata=option(parse=window_type, metavar="A:B")
    )
    """fitted window, start:end in s (required)"""
    out: Path | None = dataclasses.field(
        default=None, metadata=option(metavar="DIR", help=OUT_HELP)
    )
    """output directory (required)"""
    family: str = dataclasses.field(default="auto", metadata=option(choices=("auto", *FAMILIES)))
    """friction family; auto fits all and keeps the lowest BIC"""
    no_wob: bool = False
    """friction in N m, not proportional to the log's wob_n"""
    fix: tuple[tuple[str, float], ...] | None = dataclasses.field(
        default=None, metadata=option(parse=fix_type, metavar="NAME=VALUE", repeat=True)
    )
    """hold a parameter at a value (SI unit)"""


CALIBRATE_DESCRIPTION: Final = (
    "Fit a lumped bit-side torsional plant to a measured log (CSV or Parquet, SI\n"
    "columns time_s, top_speed_rad_s, bit_speed_rad_s, bit_torque_nm, optional wob_n):\n"
    "the measured top-drive speed drives the model; every friction family is fitted\n"
    "and the one of lowest BIC kept. Writes plant.json, report.md and figures."
)


def _parser() -> ArgumentParser:
    """The parser of ``drill-gym calibrate``."""
    return spec_parser("drill-gym calibrate", CALIBRATE_DESCRIPTION, CalibrateSpec)


def _required(parser: ArgumentParser, args: argparse.Namespace, names: Sequence[str]) -> None:
    """Report the required arguments ``names`` (dests) that are missing, as argparse would
    (checked after the parse, so that an unknown option is reported first)."""
    missing = [n for n in names if getattr(args, n) is None]
    if missing:
        shown = [n.upper() if n in ("log", "plant", "old", "new") else f"--{n}" for n in missing]
        parser.error(f"the following arguments are required: {', '.join(shown)}")


def calibrate_main(argv: Sequence[str]) -> int:
    """``drill-gym calibrate``."""
    parser = _parser()
    args = parser.parse_args(list(argv))
    _required(parser, args, ("log", "window", "out"))
    spec = spec_from_args(CalibrateSpec, args)
    assert spec.log is not None and spec.window is not None and spec.out is not None
    out = spec.out
    prepare_out(out, CALIBRATE_FILES, ("plant.json", PLANT_FORMAT.rsplit("/", 1)[0] + "/"))
    log = read_log(spec.log)
    families = FAMILIES if spec.family == "auto" else (spec.family,)
    result = calibrate(log, spec.window, families, not spec.no_wob, dict(spec.fix or ()))
    window = log.window(*spec.window)
    speed, torque = simulate_plant(result.plant, window, result.plant.initial_twist_rad)
    check_simulation(
        "the fitted plant", window, {"bit_speed_rad_s": speed, "bit_torque_nm": torque}
    )
    result.plant.save(out / "plant.json")
    title = f"{result.plant.family} fit on {spec.window[0]:g}-{spec.window[1]:g} s"
    _save(_fit_figure(window, speed, torque, title), out / "fit.png")
    _save(_loop_figure(window, speed, torque, f"torque-speed loop, {title}"), out / "loop.png")
    _save(_uncertainty_figure(result), out / "uncertainty.png")
    command = "drill-gym calibrate " + " ".join(argv)
    write_text(out / "report.md", _report(result, log, spec.window, command))
    print(f"family {result.plant.family}; wrote {', '.join(CALIBRATE_FILES)} in {printable(out)}")
    for name, p in result.plant.parameters.items():
        shown = f"{p.value:.6g} {p.unit}" if p.identified else f"not identified ({p.note})"
        print(f"  {name}: {shown}")
    return 0


def replay_rows(
    window: MeasuredLog, speed: npt.NDArray[np.float64], torque: npt.NDArray[np.float64]
) -> tuple[list[dict[str, Any]], dict[str, float], dict[str, float], dict[str, float]]:
    """The feature rows of a replay: measured, simulated, their errors, and the normalised RMS
    speed error."""
    bit = window.column("bit_speed_rad_s")
    measured_torque = window.column("bit_torque_nm")
    threshold = stuck_threshold(bit)
    measured = features(window.time_s, bit, measured_torque, threshold)
    simulated = features(window.time_s, speed, torque, threshold)
    errors = feature_errors(measured, simulated)
    nrms = float(np.sqrt(np.mean((speed - bit) ** 2)) / (np.std(bit) or 1.0))
    errors["normalised_rms_speed_error"] = nrms
    rows = [
        {
            "feature": key,
            "measured": measured[key],
            "simulated": simulated[key],
            "error": errors[key],
        }
        for key in FEATURE_KEYS
    ]
    rows.append({"feature": "normalised_rms_speed_error", "measured": 0.0, "simulated": nrms,
                 "error": nrms})  # fmt: skip
    return rows, measured, simulated, errors


def top_drive_rows(
    window: MeasuredLog,
    top_speed: npt.NDArray[np.float64],
    surface_torque: npt.NDArray[np.float64],
) -> list[dict[str, Any]]:
    """Feature rows of a free-running replay's top drive: the mean and standard deviation of
    the top speed (rad/s) and of the surface torque (N m), simulated against measured
    (relative errors), for the columns the log has."""
    rows = []
    for name, stem, unit, simulated in (
        ("top_speed_rad_s", "top_speed", "rad_s", top_speed),
        ("surface_torque_nm", "surface_torque", "nm", surface_torque),
    ):
        if not window.has(name):
            continue
        measured = window.column(name)
        for label, fn in (("mean", np.mean), ("std", np.std)):
            m, v = float(fn(measured)), float(fn(simulated))
            rows.append({"feature": f"{stem}_{label}_{unit}", "measured": m, "simulated": v,
                         "error": (v - m) / abs(m) if m else math.nan})  # fmt: skip
    return rows


@dataclasses.dataclass(frozen=True)
class ReplaySpec:
    """Settings of ``drill-gym replay``; its arguments are generated from these fields."""

    plant: str | None = dataclasses.field(
        default=None, metadata=option(positional=True, metavar="PLANT")
    )
    """plant.json written by drill-gym calibrate"""
    log: str | None = dataclasses.field(
        default=None, metadata=option(positional=True, metavar="LOG", help=LOG_HELP)
    )
    """the measured log (required)"""
    window: Window | None = dataclasses.field(
        default=None, metadata=option(parse=window_type, metavar="C:D")
    )
    """replayed window, start:end in s (required)"""
    out: Path | None = dataclasses.field(
        default=None, metadata=option(metavar="DIR", help=OUT_HELP)
    )
    """output directory (required)"""
    free_running: bool = False
    """run the plant's identified top drive under its speed loop instead of the measured top
    speed (the plant self-excites)"""


REPLAY_DESCRIPTION: Final = (
    "Drive a calibrated plant (plant.json of drill-gym calibrate) with a log's measured\n"
    "top-drive speed on a window; write the simulated bit speed and torque on bit beside\n"
    "the measured ones (replay.csv) and the stick-slip features (features.csv)."
)


def replay_parser() -> ArgumentParser:
    """The parser of ``drill-gym replay``."""
    return spec_parser("drill-gym replay", REPLAY_DESCRIPTION, ReplaySpec)


def replay_main(argv: Sequence[str]) -> int:
    """``drill-gym replay``."""
    parser = replay_parser()
    args = parser.parse_args(list(argv))
    _required(parser, args, ("plant", "log", "window", "out"))
    spec = spec_from_args(ReplaySpec, args)
    assert spec.plant is not None and spec.log is not None
    assert spec.window is not None and spec.out is not None
    out = spec.out
    prepare_out(out, REPLAY_FILES, ("replay.csv", "time_s,bit_speed_rad_s,bit_torque_nm"))
    plant = load_plant(spec.plant)
    log = read_log(spec.log)
    window = log.window(*spec.window)
    columns = {"time_s": window.time_s}
    if spec.free_running:
        top_speed, speed, torque, surface = simulate_free(plant, window)
        columns |= {"bit_speed_rad_s": speed, "bit_torque_nm": torque,
                    "top_speed_rad_s": top_speed, "surface_torque_nm": surface}  # fmt: skip
    else:
        speed, torque = simulate_plant(plant, window)
        columns |= {"bit_speed_rad_s": speed, "bit_torque_nm": torque}
    check_simulation(
        f"the plant {printable(spec.plant)}",
        window,
        {k: v for k, v in columns.items() if k != "time_s"},
    )
    for name in ("top_speed_rad_s", "bit_speed_rad_s", "bit_torque_nm", "wob_n",
                 "surface_torque_nm"):  # fmt: skip
        if window.has(name):
            columns[f"measured_{name}"] = window.column(name)
    table = np.column_stack(list(columns.values()))
    with replacing(out / "replay.csv") as f:
        np.savetxt(f, table, delimiter=",", header=",".join(columns), comments="", fmt="%.10g")
    lines = [
        "# Replay",
        "",
        f"Command: `drill-gym replay {' '.join(argv)}`",
        "",
        f"Plant: family {plant.family}, fitted on {plant.window_s[0]:g}-{plant.window_s[1]:g} s of "
        f"{plant.log}. Window: {spec.window[0]:g}-{spec.window[1]:g} s.",
        "",
        "Free running: the plant's identified top drive under its PI speed loop (initial state "
        "from the window's first samples), not the measured top speed."
        if spec.free_running
        else "Driven by the measured top-drive speed.",
        "",
    ]
    defects = [d for d in find_defects(log) if d.overlaps(*spec.window)]
    if defects:
        lines += ["Defects inside the window:", ""]
        lines += [
            f"- {d.kind} in {d.column}, {d.start_s:.6g}-{d.end_s:.6g} s: {d.detail}"
            for d in defects
        ]
        lines.append("")
    if window.has("bit_speed_rad_s") and window.has("bit_torque_nm"):
        rows, *_ = replay_rows(window, speed, torque)
        if spec.free_running:
            rows += top_drive_rows(window, columns["top_speed_rad_s"], columns["surface_torque_nm"])
        with replacing(out / "features.csv") as f:
            f.write("feature,measured,simulated,error\n")
            for r in rows:
                f.write(
                    f"{r['feature']},{r['measured']:.6g},{r['simulated']:.6g},{r['error']:.6g}\n"
                )
        lines += [
            "| feature | measured | simulated | error |",
            "|---|---|---|---|",
        ]
        for r in rows:
            kind = (
                "absolute"
                if r["feature"] in ("stuck_fraction", "normalised_rms_speed_error")
                else "relative"
            )
            lines.append(
                f"| {r['feature']} | {_format(r['measured'])} | {_format(r['simulated'])} | "
                f"{_format(r['error'], 3)} ({kind}) |"
            )
        lines += ["", "![replay](replay.png)", ""]
        mode = "free-running " if spec.free_running else ""
        title = f"{mode}replay of {spec.window[0]:g}-{spec.window[1]:g} s"
        _save(_fit_figure(window, speed, torque, title), out / "replay.png")
    else:
        lines.append("The log lacks bit_speed_rad_s or bit_torque_nm: no features compared.")
    write_text(out / "replay.md", "\n".join(lines) + "\n")
    print(f"wrote replay.csv and replay.md in {printable(out)}")
    for line in lines:
        if line.startswith("| ") and not line.startswith("| feature"):
            print(line)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym calibrate``: see :func:`calibrate_main`."""
    return calibrate_main(list(argv or []))
