"""``drill-gym replay PLANT LOG --window C:D --out DIR``: a calibrated plant driven by a log's
measured top-drive speed (see :mod:`experiments.calibrate`)."""

from __future__ import annotations

from collections.abc import Sequence

from experiments.calibrate import replay_main

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym replay``: see :func:`experiments.calibrate.replay_main`."""
    return replay_main(list(argv or []))
