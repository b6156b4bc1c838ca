"""``drill-gym``: the command line of drill-string-gym.

Subcommands (each imported only when used, so the core needs no torch):

* ``compare``: the paper's controllers on the paper's scenarios (the main job);
* ``map``: a stick-slip map over WOB and reference speed for one controller;
* ``train`` / ``evaluate``: the residual PPO agent (needs the ``[rl]`` extra).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["main"]

SUBCOMMANDS = {
    "compare": ("baselines.compare", "Compare the controllers on the paper's scenarios."),
    "map": ("baselines.stick_slip_map", "Stick-slip map over WOB x reference speed."),
    "train": ("agents.train", "Train the residual PPO agent."),
    "evaluate": ("agents.evaluate", "Evaluate a trained agent against the baselines."),
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
        if name == "compare":
            return int(module.main(rest, agent_loader=_agent_loader()) or 0)
        return int(module.main(rest) or 0)
    except (ValueError, FileNotFoundError) as err:  # user errors: one line, no traceback
        print(f"drill-gym {name}: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2


def _agent_loader() -> Callable[[], Any] | None:
    """``agents.load_default_policy`` when the agents package imports, else ``None``.

    The command line is where the packages meet: ``baselines`` never imports ``agents``."""
    try:
        agents = importlib.import_module("agents")
    except ImportError as exc:
        print(f"drill-gym: no learned agent ({exc})", file=sys.stderr)
        return None
    loader: Callable[[], Any] | None = getattr(agents, "load_default_policy", None)
    return loader


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
