"""``drill-gym``: the command line of drill-string-gym.

Subcommands, each a module with ``main(argv)`` imported only when used (so the core needs no
torch): ``compare``, ``map``, ``probability-map``, ``train``, ``sweep-train``, ``evaluate``,
``convert``, ``waves``, ``realism``, ``tune``, ``coupled``, ``benchmark``,
``calibrate``, ``replay``, ``coupled-controllers``. Every user error ends with
one line on standard error and exit code 2 (:mod:`experiments.arguments`); ``DRILL_GYM_DEBUG=1``
shows the traceback instead.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Sequence

from experiments.preflight import USAGE_ERROR, error_line_format, refused_path

__all__ = ["DEBUG_VARIABLE", "SUBCOMMANDS", "main"]

SUBCOMMANDS = {
    "compare": (
        "experiments.compare",
        "compare the controllers on the paper's scenario (table, CSV, JSON, figures)",
    ),
    "map": (
        "experiments.stick_slip_map",
        "stick-slip map of controllers over weight on bit x reference speed",
    ),
    "probability-map": (
        "experiments.probability_map",
        "probability of stick-slip over WOB (or depth) x reference speed under uncertainty",
    ),
    "train": ("experiments.train", "train the residual PPO agent (needs the rl extra)"),
    "sweep-train": (
        "experiments.sweep_train",
        "multi-seed training and hyperparameter search on Ray Tune (rl and scale extras)",
    ),
    "evaluate": (
        "experiments.evaluate",
        "score trained agents and every controller on the held-out scenarios",
    ),
    "convert": (
        "experiments.convert",
        "convert an old Stable-Baselines3 model.zip to the portable model format",
    ),
    "waves": (
        "experiments.waves",
        "torsional waves of the field string: its numbers, each controller, space-time figures",
    ),
    "realism": (
        "experiments.realism",
        "who survives realism: each controller as sensors, telemetry and top drive get real",
    ),
    "tune": (
        "experiments.tune_baselines",
        "tune the speed loops' factors with the agent's budget, scenarios and selection rule",
    ),
    "coupled": (
        "experiments.coupled",
        "the coupled axial-torsional string with the regenerative bit: standard run, stability map",
    ),
    "benchmark": (
        "experiments.benchmark",
        "score any controller or agent on the versioned suites: IQM, bootstrap intervals, profiles",
    ),
    "calibrate": (
        "experiments.calibrate",
        "fit a torsional plant to a measured log (plant.json, report, figures)",
    ),
    "replay": (
        "experiments.replay",
        "drive a calibrated plant with a log's top-drive speed; stick-slip features",
    ),
    "coupled-controllers": (
        "experiments.coupled_controllers",
        "which top-drive and axial loops hold where on the coupled string's stability map",
    ),
}
"""Subcommand name -> (module with ``main(argv)``, one line of help)."""

DEBUG_VARIABLE = "DRILL_GYM_DEBUG"
"""Environment variable: ``1`` shows the traceback of a user error instead of one line."""


def _usage() -> str:
    lines = [
        "usage: drill-gym COMMAND [options]",
        "",
        "Reference environment for torsional stick-slip control of drill strings.",
        "",
        "commands:",
    ]
    lines += [f"  {name:<16} {text}" for name, (_, text) in SUBCOMMANDS.items()]
    lines += [
        "",
        "Run 'drill-gym COMMAND --help' for the options of a command.",
        "",
        "A user error (a bad option or value, a missing file) prints one line and exits with",
        f"code 2; set {DEBUG_VARIABLE}=1 to see the full traceback instead.",
    ]
    return "\n".join(lines)


def _debug() -> bool:
    return os.environ.get(DEBUG_VARIABLE, "").strip().lower() not in ("", "0", "false", "no")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: dispatch to the subcommand module's ``main(argv)``; returns the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_usage())
        return 0
    name, rest = args[0], args[1:]
    if name in SUBCOMMANDS:  # a path no command can use is refused before any heavy import
        problem = refused_path(rest)
        if problem is not None:
            prog = f"drill-gym {name}"
            print(error_line_format.format(prog=prog, message=problem), file=sys.stderr)
            return USAGE_ERROR
    from drill_env.validation import shown
    from experiments.arguments import run_command

    if name not in SUBCOMMANDS:
        kind = "option" if name.startswith("-") else "command"
        print(
            f"drill-gym: error: unknown {kind} {shown(name)}: allowed commands "
            f"{', '.join(SUBCOMMANDS)} (see drill-gym --help)",
            file=sys.stderr,
        )
        return USAGE_ERROR
    prog = f"drill-gym {name}"

    def run() -> int:
        module = importlib.import_module(SUBCOMMANDS[name][0])
        return int(module.main(rest) or 0)

    return run_command(prog, run, debug=_debug())


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
