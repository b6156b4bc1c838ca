"""``drill-gym``: the command line of drill-string-gym.

Subcommands (each imported only when used, so the core needs no torch):

* ``compare``: the paper's controllers on the paper's scenarios (the main job);
* ``map``: a stick-slip map over WOB and reference speed for one controller;
* ``train`` / ``evaluate``: the residual PPO agent (needs the ``[rl]`` extra).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

__all__ = ["main"]

SUBCOMMANDS = {
    "compare": ("experiments.compare", "Compare the controllers on the paper's scenarios."),
    "map": ("experiments.stick_slip_map", "Stick-slip map over WOB x reference speed."),
    "train": ("agents.train", "Train the residual PPO agent."),
    "evaluate": ("experiments.evaluate", "Evaluate a trained agent against the baselines."),
}


def _usage() -> str:
    lines = ["usage: drill-gym {" + ",".join(SUBCOMMANDS) + "} [options]", "", "subcommands:"]
    lines += [f"  {name:<9} {text}" for name, (_, text) in SUBCOMMANDS.items()]
    lines.append("\nRun 'drill-gym SUBCOMMAND --help' for its options.")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: dispatch to the subcommand module's ``main(argv)``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_usage())
        return 0
    name, rest = args[0], args[1:]
    if name not in SUBCOMMANDS:
        print(f"drill-gym: unknown subcommand {name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(SUBCOMMANDS[name][0])
    try:
        return int(module.main(rest) or 0)
    except (ValueError, FileNotFoundError) as err:  # user errors: one line, no traceback
        print(f"drill-gym {name}: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
