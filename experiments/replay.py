"""``drill-gym replay PLANT LOG --window C:D --out DIR``: a calibrated plant driven by a log's
measured top-drive speed (see :mod:`experiments.calibrate`, the home of its settings,
:class:`~experiments.calibrate.ReplaySpec`, next to the replay itself)."""

from __future__ import annotations

from collections.abc import Sequence

from experiments.arguments import ArgumentParser
from experiments.calibrate import ReplaySpec, replay_main, replay_parser

__all__ = ["ReplaySpec", "main"]


def _parser() -> ArgumentParser:
    """The parser of ``drill-gym replay``, generated from :class:`ReplaySpec`."""
    return replay_parser()


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym replay``: see :func:`experiments.calibrate.replay_main`."""
    return replay_main(list(argv or []))
