"""Episode metrics of SPEC section 4, pure functions of plant-rate samples.

Every sample is one plant step (1 ms): the error ``e = V_ref - w_bit`` (true bit speed) and the
applied torque are taken at every step, whatever the agent's decision period.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np
import numpy.typing as npt

__all__ = ["METRIC_KEYS", "SEVERITY_WINDOW_S", "episode_metrics_from_samples"]

SEVERITY_WINDOW_S: Final = 20.0
"""Stick-slip severity is measured over the last this many seconds, s."""
SETTLING_BAND: Final = 0.05
"""Settling band as a fraction of the reference speed."""

METRIC_KEYS: Final = (
    "ise",
    "iae",
    "rmse",
    "rmsd_nm",
    "overshoot_pct",
    "settling_time_s",
    "chattering_nm_per_s",
    "stick_slip_severity",
    "stuck_fraction",
)


def episode_metrics_from_samples(
    bit_speed_rad_s: npt.ArrayLike,
    reference_rad_s: npt.ArrayLike,
    torque_nm: npt.ArrayLike,
    bit_stuck: npt.ArrayLike,
    dt_s: float,
) -> dict[str, Any]:
    """The SPEC section 4 metrics of one run sampled every ``dt_s`` seconds.

    Args:
        bit_speed_rad_s: True bit speed at each sample, (n,), rad/s.
        reference_rad_s: Reference bit speed at each sample, (n,), rad/s.
        torque_nm: Applied top-drive torque held from each sample to the next, (n,), N m.
        bit_stuck: Whether the bit is stuck at each sample, (n,).
        dt_s: Sample period, s.

    Returns:
        ``ise`` (rad^2/s), ``iae`` (rad), ``rmse`` (rad/s), ``rmsd_nm``, ``overshoot_pct``
        (relative to the final reference, floored at 0), ``settling_time_s`` (first time after
        which ``|e| <= 0.05 V_ref`` to the end; ``None`` if the run ends outside the band),
        ``chattering_nm_per_s`` (total variation of the torque over the run length),
        ``stick_slip_severity`` ((max - min) / (2 mean) of the bit speed over the last 20 s;
        1.0 when the bit does not turn on average there) and ``stuck_fraction``.
    """
    w = np.asarray(bit_speed_rad_s, dtype=np.float64)
    ref = np.asarray(reference_rad_s, dtype=np.float64)
    u = np.asarray(torque_nm, dtype=np.float64)
    stuck = np.asarray(bit_stuck, dtype=bool)
    n = w.shape[0]
    if n == 0 or not (ref.shape == u.shape == stuck.shape == w.shape == (n,)):
        raise ValueError(
            "samples must be non-empty 1-D arrays of one length, got shapes "
            f"{w.shape}, {ref.shape}, {u.shape}, {stuck.shape}"
        )
    if not dt_s > 0:
        raise ValueError(f"dt_s = {dt_s!r} is out of range: allowed > 0")
    e = ref - w
    duration = n * dt_s
    final_ref = ref[-1]
    outside = np.abs(e) > SETTLING_BAND * np.abs(ref)
    if not outside.any():
        settling: float | None = 0.0
    elif outside[-1]:
        settling = None
    else:
        settling = float((np.flatnonzero(outside)[-1] + 1) * dt_s)
    window = w[max(0, n - round(SEVERITY_WINDOW_S / dt_s)) :]
    mean_w = float(window.mean())
    severity = float((window.max() - window.min()) / (2 * mean_w)) if mean_w > 0 else 1.0
    overshoot = (
        (float(w.max()) - float(final_ref)) / float(final_ref) * 100 if final_ref > 0 else 0.0
    )
    return {
        "ise": float(np.sum(e * e) * dt_s),
        "iae": float(np.sum(np.abs(e)) * dt_s),
        "rmse": float(math.sqrt(np.mean(e * e))),
        "rmsd_nm": float(math.sqrt(np.mean(u * u))),
        "overshoot_pct": max(overshoot, 0.0),
        "settling_time_s": settling,
        "chattering_nm_per_s": float(np.sum(np.abs(np.diff(u))) / duration),
        "stick_slip_severity": severity,
        "stuck_fraction": float(stuck.mean()),
    }
