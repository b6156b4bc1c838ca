"""``drill-gym compare``: the controllers on the paper's scenarios, scored on the paper's metrics.

By default every registered controller (the paper's four first: ``csmc``, ``msmc``, ``asmc``,
``proposed``) runs on the docs/specification.md section 2 scenario (WOB 97,347 N, V_ref 12 rad/s, 150 s from
rest) under each Table 3 uncertainty condition, without and with 0.1 rad/s measurement noise:
32 runs for the four SMCs. When a trained residual agent is shipped (``agents``, the ``[rl]``
extra) it is added as one more row per scenario.

Every run goes through the one scoring path of the project::

    env = gym.make("DrillString-v0", randomize=False, base_controller=name, ...)
    trace = rollout(env, ZeroAction(), seed)      # the base controller acts at every 1 ms step
    row = episode_metrics(trace)                  # docs/specification.md section 4, from plant-rate samples

The decision period of the (idle) agent is long (``control_dt_s`` up to 1 s) only to keep the
Python overhead low; the controller still runs inside the compiled plant loop at 1 kHz, and the
metrics do not depend on the decision period.

Outputs (``--out``, default ``results/``): ``compare.csv`` and ``compare.json`` (one row per
run), PNG figures under ``figures/``, and a markdown table on standard output.

Example::

    drill-gym compare                                   # the default comparison
    drill-gym compare --gains rescaled                  # Table 1 gains x J_dt (see RESCALED_GAINS)
    drill-gym compare --reading controller --out results/controller-reading
    drill-gym compare --controllers csmc proposed --conditions nominal --noise 0 --duration 20
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, NamedTuple

import numpy as np
from tqdm import tqdm

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
from drill_env.control import controller_names, make_controller
from drill_env.evaluation import Trace, ZeroAction, episode_metrics, run_episode
from drill_env.metrics import METRIC_KEYS
from drill_env.parameters import PLANT_DT_S, resolve_parameters
from drill_env.scenarios import UNCERTAINTY_CONDITIONS, Scenario, SpeedProfile, WobProfile
from experiments.tables import Column, write_csv, write_json
from experiments.tables import markdown_table as _markdown

__all__ = [
    "CONDITIONS",
    "GAIN_PRESETS",
    "PAPER_CONTROLLERS",
    "RESCALED_GAINS",
    "ROW_KEYS",
    "SCENARIO",
    "default_controllers",
    "main",
    "markdown_table",
    "run_comparison",
]

PAPER_CONTROLLERS: Final = ("csmc", "msmc", "asmc", "proposed")
"""The paper's four controllers, listed first in every table."""

CONDITIONS: Final = tuple(UNCERTAINTY_CONDITIONS)
"""The Table 3 uncertainty conditions: nominal, condition1..3."""

DEFAULT_NOISE_RAD_S: Final = (0.0, 0.1)
"""Measurement noise levels of the default comparison, rad/s (docs/specification.md section 2)."""

DEFAULT_DURATION_S: Final = 150.0
"""Run length of the paper's protocol, s."""

SCENARIO: Final = Scenario(wob=WobProfile(97_347.0), reference=SpeedProfile.constant(12.0))
"""The paper's scenario (docs/specification.md section 2): constant WOB and reference, from
rest; the comparison varies its uncertainty condition, reading and noise."""

_J_DT: Final = resolve_parameters("zribi2024").J_dt

RESCALED_GAINS: Final[dict[str, dict[str, float]]] = {
    "csmc": {"k1": 3.0 * _J_DT},
    "msmc": {"k2": 3.0 * _J_DT, "k3": 0.001 * _J_DT},
    "asmc": {"mu11": 0.1 * _J_DT, "mu22": 0.01 * _J_DT, "k0": 0.2 * _J_DT},
    "proposed": {
        "mu1": 3.0 * _J_DT,
        "mu2": 0.001 * _J_DT,
        "alpha": 0.1 * _J_DT,
        "k0": 0.2 * _J_DT,
    },
}
"""The ``rescaled`` gain preset: the Table 1 gains read per unit top-drive inertia.

With the exact equivalent control, ``s' = u_disc / J_dt``: the Table 1 gains used as torques
(N m) move ``s`` by a few mrad/s^2 against about 13 kN m of load. Read instead as acting on
``s'`` directly (rad/s^2), every torque-valued gain (``k1``, ``k2``, ``k3``, the adaptive gains'
initial values ``k0``, thresholds ``alpha`` and rates ``mu``) is multiplied by
``J_dt = 930 kg m^2``; ``lam``, ``delta``, ``a`` and ``b`` are unchanged. Use as
``make_controller("proposed", **RESCALED_GAINS["proposed"])``. This is not the paper's table;
the reproduction report gives both.
"""

GAIN_PRESETS: Final[dict[str, dict[str, dict[str, float]]]] = {
    "paper": {name: {} for name in PAPER_CONTROLLERS},
    "rescaled": RESCALED_GAINS,
}
"""Gain presets by name: controller name -> gain overrides. Controllers a preset does not list
run with their own defaults (reported as ``gains = "default"``)."""

STATIC_WINDOW_S: Final = 20.0
"""``static_error_rad_s`` is the mean tracking error over the last this many seconds, s."""

ROW_KEYS: Final = (
    "controller",
    "condition",
    "noise_std_rad_s",
    *METRIC_KEYS,
    "static_error_rad_s",
    "diverged",
    "gains",
    "uncertainty_reading",
    "seed",
    "duration_s",
)
"""Columns of ``compare.csv`` and keys of each row of ``compare.json``: the docs/specification.md section 4
metrics, plus ``static_error_rad_s`` (mean of ``V_ref - w_bit`` over the last
:data:`STATIC_WINDOW_S`, the paper's "static error") and the run's settings."""

PLOT_EVERY: Final = 10
"""Plant-rate samples kept for the whole-run figures: one bin of this many (100 Hz; torques
keep each bin's extreme, see :func:`drill_env.plots.downsample`)."""

TAIL_S: Final = 0.2
"""Length of the full-rate end of each run kept for the zoomed torque figure, s."""


class RunTraces(NamedTuple):
    """What the figures need of one run."""

    overview: Trace
    """The whole run, downsampled (:data:`PLOT_EVERY`)."""
    tail: Trace
    """The last :data:`TAIL_S` seconds at full rate."""


_DECISION_PERIODS_S: Final = (1.0, 0.5, 0.25, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001)


def default_controllers() -> list[str]:
    """Every registered controller, the paper's four first, the others in registry order."""
    names = controller_names()
    return [n for n in PAPER_CONTROLLERS if n in names] + [
        n for n in names if n not in PAPER_CONTROLLERS
    ]


def decision_period(duration_s: float) -> float:
    """The longest idle-agent decision period (at most 1 s) that divides ``duration_s``.

    Raises:
        ValueError: if ``duration_s`` is not positive or not a multiple of the 1 ms plant step.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration = {duration_s!r} is out of range: allowed > 0 s")
    for dt in _DECISION_PERIODS_S:
        n = duration_s / dt
        if n >= 1 and abs(n - round(n)) < 1e-6:
            return dt
    raise ValueError(
        f"duration = {duration_s!r} is out of range: allowed a multiple of {PLANT_DT_S} s"
    )


def scenario_kwargs(
    condition: str, noise_std_rad_s: float, duration_s: float, reading: str
) -> dict[str, Any]:
    """The ``DrillString-v0`` keywords of one comparison scenario (no controller keywords)."""
    scenario = dataclasses.replace(
        SCENARIO,
        uncertainty=UNCERTAINTY_CONDITIONS[condition],
        reading="controller" if reading == "controller" else "plant",
        noise_std_rad_s=float(noise_std_rad_s),
    )
    return {**scenario.keywords(), "episode_s": float(duration_s)}


def static_error(trace: Trace, window_s: float = STATIC_WINDOW_S) -> float:
    """Mean tracking error ``V_ref - w_bit`` over the last ``window_s`` of ``trace``, rad/s."""
    n = max(1, round(window_s / trace.plant_dt_s))
    return float(np.mean(trace.reference_rad_s[-n:] - trace.bit_speed_rad_s[-n:]))


def _row(
    controller: str,
    condition: str,
    noise: float,
    metrics: Mapping[str, Any],
    gains: str,
    reading: str,
    seed: int,
    duration_s: float,
) -> dict[str, Any]:
    row: dict[str, Any] = {
        "controller": controller,
        "condition": condition,
        "noise_std_rad_s": float(noise),
    }
    for key in (*METRIC_KEYS, "static_error_rad_s"):
        row[key] = metrics[key]
    row["diverged"] = bool(metrics["diverged"])
    row["gains"] = gains
    row["uncertainty_reading"] = reading
    row["seed"] = seed
    row["duration_s"] = duration_s
    return row


def run_comparison(
    controllers: Sequence[str],
    conditions: Sequence[str],
    noises: Sequence[float],
    *,
    duration_s: float = DEFAULT_DURATION_S,
    seed: int = 0,
    reading: str = "plant",
    gains: str = "paper",
    agent: Any = None,
    keep_traces: bool = True,
    progress: bool = True,
) -> tuple[list[dict[str, Any]], dict[tuple[str, str, float], RunTraces]]:
    """Run every controller (and ``agent``) on every condition and noise level.

    Args:
        controllers: Registered controller names.
        conditions: Table 3 condition names.
        noises: Measurement noise levels, rad/s.
        duration_s: Run length, s.
        seed: Reset seed of every run (it drives the noise).
        reading: Uncertainty reading, ``plant`` or ``controller``.
        gains: Gain preset name (:data:`GAIN_PRESETS`).
        agent: ``None``, or a policy with ``predict``, ``env_kwargs`` and ``name``.
        keep_traces: Keep light copies of the traces (:class:`RunTraces`) for figures.
        progress: Show a progress bar on standard error.

    Returns:
        The rows (see :data:`ROW_KEYS`) and the traces by ``(controller, condition, noise)``.
    """
    preset = GAIN_PRESETS[gains]
    dt = decision_period(duration_s)
    labels = [(c, False) for c in controllers]
    if agent is not None:
        labels.append((str(agent.name), True))
    jobs = [(c, a, cond, float(n)) for c, a in labels for cond in conditions for n in noises]
    rows: list[dict[str, Any]] = []
    traces: dict[tuple[str, str, float], RunTraces] = {}
    bar = tqdm(jobs, desc="compare", unit="run", file=sys.stderr, disable=not progress)
    for label, is_agent, cond, noise in bar:
        bar.set_postfix_str(f"{label} {cond} noise={noise:g}", refresh=False)
        scenario = scenario_kwargs(cond, noise, duration_s, reading)
        if is_agent:
            own = {k: v for k, v in dict(agent.env_kwargs).items() if k != "max_episode_steps"}
            kwargs = {**own, **scenario}
            trace = run_episode(kwargs, agent, seed)
            gain_label = "agent"
        else:
            overrides = preset.get(label)
            controller = make_controller(label, **(overrides or {}))
            kwargs = {**scenario, "base_controller": controller, "control_dt_s": dt}
            trace = run_episode(kwargs, ZeroAction(), seed)
            gain_label = gains if overrides is not None else "default"
        metrics = {**episode_metrics(trace), "static_error_rad_s": static_error(trace)}
        rows.append(_row(label, cond, noise, metrics, gain_label, reading, seed, duration_s))
        if keep_traces:
            from experiments.plots import downsample, time_window

            traces[(label, cond, noise)] = RunTraces(
                downsample(trace, PLOT_EVERY),
                time_window(trace, max(trace.duration_s - TAIL_S, 0.0)),
            )
    return rows, traces


# ----------------------------------------------------------------------------- output
TABLE_COLUMNS: Final = (
    Column("controller", "controller", align="left"),
    Column("condition", "condition", align="left"),
    Column("noise_std_rad_s", "noise (rad/s)", "{:g}"),
    Column("ise", "ISE", "{:.1f}"),
    Column("iae", "IAE", "{:.1f}"),
    Column("rmse", "RMSE (rad/s)", "{:.3f}"),
    Column("static_error_rad_s", "static error (rad/s)", "{:.2f}"),
    Column("rmsd_nm", "RMSD (N m)", "{:,.0f}"),
    Column("overshoot_pct", "overshoot %", "{:.1f}"),
    Column("settling_time_s", "settling (s)", "{:.1f}", missing="never"),
    Column("chattering_nm_per_s", "chattering (N m/s)", "{:,.0f}"),
    Column("stick_slip_severity", "severity", "{:.3f}"),
    Column("stuck_fraction", "stuck fraction", "{:.3f}"),
)
"""The columns of the comparison's markdown table."""


def _diverged_cell(row: Mapping[str, Any], column: Column) -> str | None:
    if column.key == "settling_time_s" and row.get("diverged"):
        return "diverged"
    return None


def markdown_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """The rows as a markdown table (settling ``never``: the run ends outside the 5 % band;
    static error: mean of ``V_ref - w_bit`` over the last 20 s)."""
    return _markdown(rows, TABLE_COLUMNS, _diverged_cell)


def write_figures(
    rows: Sequence[Mapping[str, Any]],
    runs: Mapping[tuple[str, str, float], RunTraces],
    folder: Path,
) -> list[Path]:
    """The comparison's figures in ``folder``, in the spirit of the paper's Figs 3-12.

    * ``speed_torque_<controller>.png``: bit speed and torque under each condition, noise off
      (Figs 6-9);
    * ``noise_speed_torque.png``: every controller with noise on (Figs 3-4a);
      ``noise_torque_zoom.png``: the torque of each controller over the last 0.2 s at full rate,
      without and with noise (Fig 4b);
    * ``bars_rmse.png``, ``bars_ise_iae.png`` (noise off, by condition), ``bars_rmsd.png`` and
      ``bars_chattering.png`` (first condition, with and without noise) (Figs 5, 10-12);
    * ``adaptive_gains.png``: the adaptive gains against time (noise off).
    """
    from experiments.plots import (
        plot_adaptive_gains,
        plot_metric_bars,
        plot_panels,
        plot_speed_and_torque,
    )

    folder.mkdir(parents=True, exist_ok=True)
    traces = {key: run.overview for key, run in runs.items()}
    labels = list(dict.fromkeys(r["controller"] for r in rows))
    conditions = list(dict.fromkeys(r["condition"] for r in rows))
    noises = sorted({float(r["noise_std_rad_s"]) for r in rows})
    quiet, loud = noises[0], noises[-1]
    first = conditions[0]
    out: list[Path] = []
    for label in labels:
        by_condition = {
            c: traces[(label, c, quiet)] for c in conditions if (label, c, quiet) in traces
        }
        out.append(
            plot_speed_and_torque(
                by_condition,
                folder / f"speed_torque_{label}.png",
                f"{label}: Table 3 conditions, noise {quiet:g} rad/s",
            )
        )
    noisy = {lab: traces[(lab, first, loud)] for lab in labels if (lab, first, loud) in traces}
    if noisy:
        out.append(
            plot_speed_and_torque(
                noisy, folder / "noise_speed_torque.png", f"{first}, noise {loud:g} rad/s"
            )
        )
        panels = {
            lab: {
                f"noise {n:g} rad/s": runs[(lab, first, n)].tail
                for n in (quiet, loud)
                if (lab, first, n) in runs
            }
            for lab in labels
        }
        out.append(
            plot_panels(
                panels,
                folder / "noise_torque_zoom.png",
                f"top-drive torque at 1 kHz, {first}, last {TAIL_S:g} s",
            )
        )
    quiet_rows = [r for r in rows if float(r["noise_std_rad_s"]) == quiet]
    first_rows = [r for r in rows if r["condition"] == first]
    out.append(
        plot_metric_bars(
            quiet_rows, "rmse", folder / "bars_rmse.png", title=f"RMSE, noise {quiet:g} rad/s"
        )
    )
    out.append(
        plot_metric_bars(
            quiet_rows,
            ("ise", "iae"),
            folder / "bars_ise_iae.png",
            title=f"ISE and IAE, noise {quiet:g} rad/s",
        )
    )
    out.append(
        plot_metric_bars(
            first_rows,
            "rmsd_nm",
            folder / "bars_rmsd.png",
            hue="noise_std_rad_s",
            title=f"RMSD with and without noise ({first})",
        )
    )
    out.append(
        plot_metric_bars(
            first_rows,
            "chattering_nm_per_s",
            folder / "bars_chattering.png",
            hue="noise_std_rad_s",
            title=f"chattering with and without noise ({first})",
            log=True,
        )
    )
    gains = {
        f"{lab} {c}": traces[(lab, c, quiet)]
        for lab in labels
        for c in conditions
        if (lab, c, quiet) in traces and np.any(traces[(lab, c, quiet)].adaptive_gain != 0.0)
    }
    out.append(
        plot_adaptive_gains(
            gains, folder / "adaptive_gains.png", f"adaptive gains, noise {quiet:g} rad/s"
        )
    )
    return out


# ---------------------------------------------------------------------------- the agent
def load_agent(loader: Callable[[], Any] | None = None) -> Any:
    """The shipped agent (``agents.load_default_policy``, or ``loader()`` when given): a policy
    with ``predict``, ``env_kwargs`` and ``name``, or ``None``.

    ``None`` when the loader needs a missing package or no model is shipped; a model that fails
    to load is reported on standard error and skipped.
    """
    if loader is None:
        from agents import load_default_policy

        loader = load_default_policy
    try:
        policy = loader()
    except ImportError as exc:
        print(f"compare: no agent row ({exc})", file=sys.stderr)
        return None
    except Exception as exc:  # a broken model must not stop the baseline comparison
        print(f"compare: the shipped agent failed to load, skipped: {exc!r}", file=sys.stderr)
        return None
    return policy


# -------------------------------------------------------------------------------- CLI
def _non_negative(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"noise must be a finite number >= 0, got {text!r}")
    return value


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="drill-gym compare",
        description=(
            "Compare the controllers on the paper's scenarios (docs/specification.md section 2): each controller "
            "x uncertainty condition x noise level, scored by rollout + episode_metrics."
        ),
    )
    p.add_argument(
        "--controllers",
        nargs="+",
        metavar="NAME",
        help="registered controller names (default: all, the paper's four first)",
    )
    p.add_argument(
        "--conditions",
        nargs="+",
        choices=CONDITIONS,
        default=list(CONDITIONS),
        help="Table 3 uncertainty conditions (default: all four)",
    )
    p.add_argument(
        "--noise",
        nargs="+",
        type=_non_negative,
        default=list(DEFAULT_NOISE_RAD_S),
        metavar="STD",
        help="measurement noise levels, rad/s (default: 0 0.1)",
    )
    p.add_argument(
        "--duration", type=float, default=DEFAULT_DURATION_S, help="run length, s (default 150)"
    )
    p.add_argument("--seed", type=int, default=0, help="reset seed of every run (default 0)")
    p.add_argument(
        "--out", type=Path, default=Path("results"), help="output folder (default results/)"
    )
    p.add_argument(
        "--reading",
        choices=("plant", "controller"),
        default="plant",
        help="uncertainty reading: scale the true plant (default) or the controllers' model",
    )
    p.add_argument(
        "--gains",
        choices=tuple(GAIN_PRESETS),
        default="paper",
        help="gain preset: Table 1 (paper, default) or Table 1 x J_dt (rescaled)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--no-agent", action="store_true", help="leave out the shipped residual agent")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None, agent_loader: Callable[[], Any] | None = None) -> int:
    """Run the comparison; print the table; write CSV, JSON and figures. Returns 0.

    ``agent_loader`` returns the learned agent to add as a row (``None``: the shipped one).
    """
    parser = _parser()
    args = parser.parse_args(argv)
    registered = controller_names()
    controllers = list(args.controllers) if args.controllers else default_controllers()
    unknown = [c for c in controllers if c not in registered]
    if unknown:
        parser.error(
            f"unknown controller(s) {', '.join(unknown)}: valid names are {', '.join(registered)}"
        )
    try:
        decision_period(args.duration)
    except ValueError as exc:
        parser.error(str(exc))
    agent = None if args.no_agent else load_agent(agent_loader)
    start = time.perf_counter()
    rows, traces = run_comparison(
        list(dict.fromkeys(controllers)),
        list(dict.fromkeys(args.conditions)),
        list(dict.fromkeys(args.noise)),
        duration_s=args.duration,
        seed=args.seed,
        reading=args.reading,
        gains=args.gains,
        agent=agent,
        keep_traces=not args.no_plots,
        progress=not args.no_progress,
    )
    simulated = time.perf_counter() - start
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    print(
        f"Scenario: WOB {SCENARIO.wob.initial_n:,.0f} N, V_ref {SCENARIO.reference.value(0.0):g} "
        f"rad/s, {args.duration:g} s from rest; uncertainty reading '{args.reading}', gains "
        f"'{args.gains}', seed {args.seed}.\n"
    )
    print(markdown_table(rows))
    written = [
        write_csv(rows, out / "compare.csv", ROW_KEYS),
        write_json([{k: r[k] for k in ROW_KEYS} for r in rows], out / "compare.json"),
    ]
    if not args.no_plots:
        written += write_figures(rows, traces, out / "figures")
    total = time.perf_counter() - start
    print(
        f"\n{len(rows)} runs simulated in {simulated:.1f} s ({total:.1f} s with output); "
        f"wrote {len(written)} files to {out}/"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
