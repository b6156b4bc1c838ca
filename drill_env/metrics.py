"""Episode metrics of docs/specification.md section 4, pure functions of plant-rate samples.

Every sample is one plant step (1 ms): the error ``e = V_ref - w_bit`` (true bit speed) and the
applied torque are taken at every step, whatever the agent's decision period.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env.validation import shown

__all__ = [
    "IQM_TRIM",
    "METRIC_KEYS",
    "METRIC_LABELS",
    "SEVERITY_WINDOW_S",
    "STEADY_SEVERITY",
    "STICK_SLIP_SEVERITY",
    "WindowStatistics",
    "episode_metrics_from_samples",
    "interquartile_mean",
    "stick_slip_severity",
]

SEVERITY_WINDOW_S: Final = 20.0
"""Stick-slip severity is measured over the last this many seconds, s."""
SETTLING_BAND: Final = 0.05
"""Settling band as a fraction of the reference speed."""
STICK_SLIP_SEVERITY: Final = 0.5
"""A run stick-slips when its severity exceeds this (or its bit sticks) in the window."""
STEADY_SEVERITY: Final = 0.1
"""Below this severity a run turns steadily (it has no stick-slip cycle to time)."""
IQM_TRIM: Final = 0.25
"""Share of the values the interquartile mean cuts from each end."""

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

METRIC_LABELS: Final[dict[str, str]] = {
    "ise": "ISE (rad$^2$/s)",
    "iae": "IAE (rad)",
    "rmse": "RMSE (rad/s)",
    "rmsd_nm": "RMSD of the torque (N m)",
    "overshoot_pct": "overshoot (%)",
    "settling_time_s": "settling time (s)",
    "chattering_nm_per_s": "chattering (N m/s)",
    "stick_slip_severity": "stick-slip severity",
    "stuck_fraction": "stuck fraction",
}
"""Axis label (with unit) of each key of :data:`METRIC_KEYS`."""


def interquartile_mean(values: Any, axis: int | None = None) -> Any:
    """Interquartile mean: the mean of ``values`` after cutting ``int(IQM_TRIM * n)`` of the
    ``n`` values from each end, along ``axis`` (``None``: all values, flattened). The
    estimator of rliable and of ``scipy.stats.trim_mean(values, 0.25)``, in numpy.

    Raises:
        ValueError: no value to average.
    """
    array = np.asarray(values, dtype=float)
    if axis is None:
        array, axis = array.ravel(), 0
    count = array.shape[axis]
    if count == 0:
        raise ValueError("interquartile_mean of no values: allowed at least one value")
    low = int(IQM_TRIM * count)
    ordered = np.partition(array, (low, count - low - 1), axis=axis)
    middle = [slice(None)] * ordered.ndim
    middle[axis] = slice(low, count - low)
    return np.mean(ordered[tuple(middle)], axis=axis)


def stick_slip_severity(high: Any, low: Any, mean: Any) -> Any:
    """``(max - min) / (2 mean)`` of the bit speed over a window, from its maximum, minimum and
    mean (rad/s); 1.0 where the bit does not turn on average (``mean <= 0``). Floats or arrays
    (elementwise)."""
    if isinstance(mean, np.ndarray):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(mean > 0, (high - low) / (2.0 * mean), 1.0)
    return float((high - low) / (2 * mean)) if mean > 0 else 1.0


class WindowStatistics:
    """Running maximum, minimum and sum of the bit speed and the count of stuck samples of
    ``num`` strings over a window, fed chunk by chunk, so that a long run's stick-slip severity
    and stuck fraction need no memory of its samples.

    Args:
        num: Number of strings.
    """

    def __init__(self, num: int) -> None:
        self.high = np.full(num, -np.inf)
        self.low = np.full(num, np.inf)
        self.total = np.zeros(num)
        self.stuck = np.zeros(num)
        self.samples = 0

    def add(self, bit_speed_rad_s: npt.NDArray[np.float64], bit_stuck: npt.ArrayLike) -> None:
        """Take in a chunk: bit speed (num, n) in rad/s and stuck flags (num, n)."""
        np.maximum(self.high, bit_speed_rad_s.max(axis=1), out=self.high)
        np.minimum(self.low, bit_speed_rad_s.min(axis=1), out=self.low)
        self.total += bit_speed_rad_s.sum(axis=1)
        self.stuck += np.asarray(bit_stuck).sum(axis=1)
        self.samples += bit_speed_rad_s.shape[1]

    def severity(self) -> npt.NDArray[np.float64]:
        """Stick-slip severity of each string over the samples taken in, (num,)."""
        result: npt.NDArray[np.float64] = stick_slip_severity(
            self.high, self.low, self.total / self.samples
        )
        return result

    def stuck_fraction(self) -> npt.NDArray[np.float64]:
        """Share of the samples with the bit stuck, (num,)."""
        return self.stuck / self.samples


def episode_metrics_from_samples(
    bit_speed_rad_s: npt.ArrayLike,
    reference_rad_s: npt.ArrayLike,
    torque_nm: npt.ArrayLike,
    bit_stuck: npt.ArrayLike,
    dt_s: float,
) -> dict[str, Any]:
    """The docs/specification.md section 4 metrics of one run sampled every ``dt_s`` seconds.

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
        raise ValueError(f"dt_s = {shown(dt_s)} is out of range: allowed > 0")
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
    severity = stick_slip_severity(float(window.max()), float(window.min()), float(window.mean()))
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
