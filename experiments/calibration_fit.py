"""Fitting the bit-side model of :mod:`drill_env.bit_model` to a measured log
(docs/calibration.md section 2): direct first estimates, a Levenberg-Marquardt output-error
fit of the simulated bit speed and torque on bit, identifiability from the Laplace
covariance, the choice of the friction family by an information criterion, and the
stick-slip features that compare a replay with the log.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Protocol

import numpy as np
import numpy.typing as npt

from drill_env.bit_model import (
    FAMILIES,
    N_MODEL_PARAMS,
    P_A0,
    P_AA,
    P_C,
    P_CV,
    P_J,
    P_K,
    P_TAU,
    P_XI,
    STRING_KEYS,
    TOP_DRIVE_KEYS,
    simulate_bit,
    simulate_free_running,
    simulate_top_side,
    substeps_for,
)
from drill_env.calibrated_plant import (
    FAMILY_PARAMETERS,
    MODEL_PARAMETERS,
    PARAMETER_RANGES,
    CalibratedPlant,
    FittedParameter,
    check_parameter,
    parameter_range_text,
    parameter_unit,
)
from drill_env.measured_log import Defect, MeasuredLog, find_defects, spike_mask
from drill_env.validation import shown

__all__ = [
    "FEATURE_KEYS",
    "FitResult",
    "calibrate",
    "features",
    "initial_estimates",
    "identify_string",
    "identify_top_drive",
    "simulate_free",
    "simulate_plant",
]

MAX_RELATIVE_STD: Final = 0.25
"""A parameter whose fitted relative standard deviation exceeds this is not identified."""
MEMORY_TIMES_S: Final = (0.003, 0.01, 0.03, 0.1, 0.3)
"""Starting memory times of the ``memory`` family's fit, s."""
STARTS_REFINED: Final = 3
"""The fit runs Levenberg-Marquardt from this many of its starting points (those of lowest
initial cost) and keeps the best end."""
FEATURE_KEYS: Final = (
    "period_fft_s",
    "period_cycles_s",
    "bit_speed_p2p_rad_s",
    "bit_torque_p2p_nm",
    "bit_torque_mean_nm",
    "stuck_fraction",
)
"""The stick-slip features of a window, units in the names."""


WOB_SMOOTHING_S: Final = 0.1
"""Length of the centred moving average of the measured WOB that scales the friction torques
in the simulations, s (WOB varies slowly; its sensor noise, fed raw into the static
threshold, would make the break-away time jump with the parameters and the cost rough)."""


def wob_input(log: MeasuredLog) -> npt.NDArray[np.float64]:
    """The WOB (N) that scales the simulated friction: the measured ``wob_n`` under a centred
    moving average of :data:`WOB_SMOOTHING_S` (shorter windows at the ends; unchanged when
    the samples are farther apart than that)."""
    wob = log.column("wob_n")
    half = int(WOB_SMOOTHING_S / (2 * log.sample_period_s))
    if half < 1 or wob.size < 3:
        return wob
    kernel = np.ones(2 * half + 1)
    total = np.convolve(wob, kernel, mode="same")
    count = np.convolve(np.ones_like(wob), kernel, mode="same")
    return np.asarray(total / count)


def _speed0(speed: npt.NDArray[np.float64], threshold: float) -> float:
    value = float(np.median(speed[:5]))
    return 0.0 if abs(value) < threshold else value


def stuck_threshold(bit_speed: npt.NDArray[np.float64]) -> float:
    """Speed below which the bit counts as stuck, rad/s: 5 % of the measured speed's 1-99 %
    range (so that noise around 0 counts as stuck)."""
    return 0.05 * float(np.percentile(bit_speed, 99) - np.percentile(bit_speed, 1))


@dataclass
class MomentumBalance:
    """The bit's momentum balance integrated once over a window, ``J w_b(t) - k int(twist) -
    c twist + int(T_bit) = a + b t`` with the twist integrated from the measured speeds
    (``a``, ``b`` absorb the initial speed and twist): linear in ``J, k, c`` and independent
    of the friction law. Its residual, with ``a, b`` projected out, joins the fit's
    residuals when the window's direct estimates are consistent (fine sampling, one
    inertia), so that the string's inertia and stiffness are those of the measured momentum
    balance and not traded against the friction's shape."""

    bit: npt.NDArray[np.float64]
    twist_integral: npt.NDArray[np.float64]
    twist: npt.NDArray[np.float64]
    torque_integral: npt.NDArray[np.float64]
    nuisance: npt.NDArray[np.float64]  # orthonormal basis of (1, t), shape (n, 2)
    scale: float

    @classmethod
    def of(cls, log: MeasuredLog) -> MomentumBalance:
        t = log.time_s - log.time_s[0]
        dt = np.diff(t)

        def cumulative(y: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * dt)))

        bit, _ = driving_bit_speed(log)
        twist = cumulative(log.column("top_speed_rad_s") - bit)
        q, _ = np.linalg.qr(np.column_stack([np.ones_like(t), t]))
        torque_integral = cumulative(log.column("bit_torque_nm"))
        centred = torque_integral - q @ (q.T @ torque_integral)
        return cls(bit, cumulative(twist), twist, torque_integral, q, float(np.std(centred)) or 1.0)

    def residuals(self, p: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        e = p[P_J] * self.bit - p[P_K] * self.twist_integral - p[P_C] * self.twist
        e = e + self.torque_integral
        return np.asarray((e - self.nuisance @ (self.nuisance.T @ e)) / self.scale)


def _balance_estimates(log: MeasuredLog) -> tuple[float, float, float, float, bool]:
    """``(J, k, k twist0, c, consistent)`` by least squares on the integrated momentum balance;
    ``consistent`` when ``J, k > 0`` and ``k`` within a factor 2 of the stuck phases' slope
    (or no stuck phases)."""
    t = log.time_s - log.time_s[0]
    dt = np.diff(t)

    def cumulative(y: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * dt)))

    top = log.column("top_speed_rad_s")
    bit, _ = driving_bit_speed(log)
    torque = log.column("bit_torque_nm")
    twist_rel = cumulative(top - bit)
    a = np.column_stack([bit, -cumulative(twist_rel), -t, -twist_rel, -np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(a, -cumulative(torque), rcond=None)
    j_est, k_est, kx0, c_est, _ = (float(v) for v in coef)
    stick_k, _ = _stick_slip_estimates(t, top, bit, torque)
    consistent = j_est > 0 and k_est > 0 and (stick_k <= 0 or 0.5 < k_est / stick_k < 2.0)
    return j_est, k_est, kx0, c_est, consistent


def initial_estimates(log: MeasuredLog, uses_wob: bool) -> tuple[npt.NDArray[np.float64], float]:
    """Direct estimates of the model parameters and the initial twist from the window.

    The bit's momentum balance integrated once, ``J (w_b(t) - w_b(0)) = k int(twist) +
    c (twist - twist0) - int(T_bit)`` with the twist integrated from the measured speeds,
    is linear in ``J``, ``k``, ``k twist0`` and ``c`` (least squares); the friction follows
    from the torque on bit while slipping (a grid over the Stribeck rate, least squares for
    the rest) and the largest torque while stuck.

    Returns:
        ``(p, twist0_rad)``: the model vector (memory time 0.03 s) and the initial twist.
    """
    t = log.time_s - log.time_s[0]
    top = log.column("top_speed_rad_s")
    bit = log.column("bit_speed_rad_s")
    torque = log.column("bit_torque_nm")
    j_est, k_est, kx0, c_est, consistent = _balance_estimates(log)
    p = np.zeros(N_MODEL_PARAMS)
    if not consistent:  # the equation error failed (coarse sampling, a string with more inertias)
        stick_k, stick_j = _stick_slip_estimates(t, top, bit, torque)
        j_est, k_est, c_est = stick_j, stick_k, 0.0
        kx0 = float(np.median(torque[:5]))
    p[P_J] = j_est if j_est > 0 else 1.0
    p[P_K] = k_est if k_est > 0 else 1.0
    p[P_C] = max(c_est, 1e-3 * math.sqrt(p[P_K] * p[P_J]))
    twist0 = kx0 / p[P_K]
    scale = log.column("wob_n") if uses_wob else np.ones_like(t)
    threshold = stuck_threshold(bit)
    slip = np.abs(bit) > threshold
    per = torque / scale
    stuck_values = np.abs(per[~slip])
    static_max = float(np.percentile(stuck_values, 99)) if stuck_values.size > 10 else 0.0
    best = (math.inf, 0.0, 0.0, 0.0, 0.5)
    if slip.sum() > 10:
        speed = np.abs(bit[slip])
        y = per[slip] * np.sign(bit[slip])
        for xi in np.geomspace(1e-2 / max(speed.mean(), 1e-9), 10 / max(speed.mean(), 1e-9), 40):
            viscous = speed / scale[slip]
            for columns in (3, 2):
                basis = np.column_stack([np.ones_like(speed), np.exp(-xi * speed), viscous])
                basis = basis[:, :columns]
                norms = np.linalg.norm(basis, axis=0)
                sol, *_ = np.linalg.lstsq(basis / norms, y, rcond=None)
                sol = sol / norms
                cost = float(np.sum((basis @ sol - y) ** 2))
                if cost < best[0] and np.all(sol >= 0) and sol[0] > 0:
                    c_v = float(sol[2]) if columns == 3 else 0.0
                    best = (cost, float(sol[0]), float(sol[1]), c_v, xi)
    _, a_0, drop, c_v, xi = best
    if a_0 <= 0:
        a_0 = float(np.median(np.abs(per[slip]))) if slip.any() else float(np.median(np.abs(per)))
    p[P_A0] = a_0
    p[P_AA] = max(a_0 + drop, static_max, 1.01 * a_0)
    p[P_XI] = xi
    p[P_CV] = max(c_v, 1e-3 * p[P_C] + 1e-12)
    p[P_TAU] = 0.03
    return p, twist0


SEGMENT_CYCLES: Final = 2
"""Stick-slip cycles per segment of the multiple-shooting stage: with two, each segment
predicts a whole stick phase (its length sets the period) from the state of the one before."""
SEGMENT_MIN_STUCK_S: Final = 0.02
"""Shortest measured stuck run that starts a segment of the multiple-shooting stage, s."""


def stuck_segments(
    log: MeasuredLog, cycles: int = SEGMENT_CYCLES
) -> list[tuple[int, int, float, int, int]] | None:
    """Segments ``(first, end, torque, run_first, run_end)`` of the multiple-shooting stage of
    the fit: each starts in the middle of every ``cycles``-th measured stuck run (``|bit
    speed|`` below :func:`stuck_threshold` for :data:`SEGMENT_MIN_STUCK_S`) and ends where the
    next starts; ``torque`` is the median measured torque of its first 5 samples and
    ``run_first:run_end`` the stuck run without its 2 first and last samples (from which the
    fit estimates the starting torque, :meth:`_Problem.simulate`). None with fewer than 2
    stuck runs (no stick-slip)."""
    bit = log.column("bit_speed_rad_s")
    torque = log.column("bit_torque_nm")
    stuck = np.abs(bit) < stuck_threshold(bit)
    padded = np.concatenate(([0], stuck.astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(padded))
    runs = []
    min_samples = max(5, int(SEGMENT_MIN_STUCK_S / log.sample_period_s))
    for a, b in zip(edges[::2], edges[1::2], strict=False):
        if b - a >= min_samples:
            runs.append((int(a + b) // 2, int(a) + 2, int(b) - 2))
    if len(runs) < 2:
        return None
    runs = runs[::cycles]
    ends = [r[0] for r in runs[1:]] + [bit.size]
    return [
        (a, b, float(np.median(torque[a : a + 5])), lo, hi)
        for (a, lo, hi), b in zip(runs, ends, strict=False)
        if b - a >= 3
    ]


def _stick_slip_estimates(
    t: npt.NDArray[np.float64],
    top: npt.NDArray[np.float64],
    bit: npt.NDArray[np.float64],
    torque: npt.NDArray[np.float64],
) -> tuple[float, float]:
    """``(k, J)`` from the stick-slip cycles: while the bit is stuck the torque on bit rises
    with the twist the top drive winds (slope ``k``, least squares on every stuck run of 4 or
    more samples); a slip lasts about half a natural period, ``J = k (t_slip / pi)^2``.
    ``(0, 0)`` without stuck runs."""
    stuck = np.abs(bit) < stuck_threshold(bit)
    padded = np.concatenate(([0], stuck.astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(padded))
    xs, ys = [], []
    for a, b in zip(edges[::2], edges[1::2], strict=False):
        if b - a >= 4:
            dt = np.diff(t[a:b])
            twist = np.concatenate(([0.0], np.cumsum(0.5 * (top[a + 1 : b] + top[a : b - 1]) * dt)))
            xs.append(twist - twist.mean())
            ys.append(torque[a:b] - torque[a:b].mean())
    if not xs:
        return 0.0, 0.0
    x, y = np.concatenate(xs), np.concatenate(ys)
    k = float(x @ y / (x @ x)) if x @ x > 0 else 0.0
    slips = [t[b] - t[a] for a, b in zip(edges[1::2][:-1], edges[2::2], strict=False) if b > a]
    if k <= 0 or not slips:
        return 0.0, 0.0
    return k, k * (float(np.median(slips)) / math.pi) ** 2


@dataclass
class _Problem:
    """The residuals of one window for one family."""

    log: MeasuredLog
    family: str
    uses_wob: bool
    free: list[str]
    fixed_p: npt.NDArray[np.float64]
    weights: npt.NDArray[np.float64]  # per residual, 0 where excluded
    scales: tuple[float, float]
    speed0: float
    substeps: int
    twist0_fixed: float = 0.0
    segments: list[tuple[int, int, float, int, int]] | None = None
    balance: MomentumBalance | None = None
    _angle: npt.NDArray[np.float64] | None = None  # the top drive's measured angle, rad

    def unpack(self, theta: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float]:
        p = self.fixed_p.copy()
        for i, name in enumerate(self.free):
            if name == "initial_twist":
                continue
            if name == "sliding_friction":
                continue
            p[MODEL_PARAMETERS[name][0]] = math.exp(theta[i])
        if "sliding_friction" in self.free:
            i = self.free.index("sliding_friction")
            p[P_A0] = p[P_AA] / (1.0 + math.exp(-theta[i]))
        if "initial_twist" in self.free:
            twist0 = theta[self.free.index("initial_twist")] * self.twist_scale(p)
        else:
            twist0 = self.twist0_fixed
        return p, twist0

    def twist_scale(self, p: npt.NDArray[np.float64]) -> float:
        scale = float(np.mean(self.log.column("wob_n"))) if self.uses_wob else 1.0
        return p[P_AA] * scale / p[P_K]

    def pack(self, p: npt.NDArray[np.float64], twist0: float) -> npt.NDArray[np.float64]:
        theta = np.zeros(len(self.free))
        for i, name in enumerate(self.free):
            if name == "initial_twist":
                theta[i] = twist0 / self.twist_scale(p)
            elif name == "sliding_friction":
                ratio = min(max(p[P_A0] / p[P_AA], 1e-6), 1 - 1e-9)
                theta[i] = math.log(ratio / (1 - ratio))
            else:
                theta[i] = math.log(max(p[MODEL_PARAMETERS[name][0]], 1e-300))
        return theta

    def simulate(
        self, theta: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        p, twist0 = self.unpack(theta)
        top = self.log.column("top_speed_rad_s")
        wob = wob_input(self.log) if self.uses_wob else None
        if self.segments is None:
            speed, torque, _ = simulate_bit(
                self.log.time_s, top, p, self.family, twist0, self.speed0, wob, self.substeps
            )
            return speed, torque
        # Multiple shooting: every segment starts stuck, its twist from the measured torque of
        # its whole stuck run: while stuck the torque on bit is the string's, T(t) = T(a) +
        # k (angle(t) - angle(a)) + c (w_t(t) - w_t(a)) with the top drive's measured angle,
        # so each sample of the run estimates T(a) (their median: a few ms of one sample's
        # noise would move the break-away, and the fit would buy it back with the friction).
        speed = self.log.column("bit_speed_rad_s").copy()
        torque = self.log.column("bit_torque_nm").copy()
        measured = self.log.column("bit_torque_nm")
        if self._angle is None:
            self._angle = _cumulative(self.log.time_s, top)
        angle = self._angle
        for a, b, _, lo, hi in self.segments:
            start = measured[lo:hi] - p[P_K] * (angle[lo:hi] - angle[a])
            start = start - p[P_C] * (top[lo:hi] - top[a])
            torque0 = float(np.median(start))
            s, q, _ = simulate_bit(
                self.log.time_s[a:b], top[a:b], p, self.family, (torque0 - p[P_C] * top[a]) / p[P_K],
                0.0, None if wob is None else wob[a:b], self.substeps,
            )  # fmt: skip
            speed[a:b] = s
            torque[a:b] = q
        return speed, torque

    def residuals(self, theta: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        speed, torque = self.simulate(theta)
        r = np.concatenate(
            [
                (speed - self.log.column("bit_speed_rad_s")) / self.scales[0],
                (torque - self.log.column("bit_torque_nm")) / self.scales[1],
            ]
        )
        if self.balance is not None:
            r = np.concatenate([r, self.balance.residuals(self.unpack(theta)[0])])
        r = np.where(np.isfinite(r), r, 1e3)
        return np.asarray(r * self.weights[: r.size])


def _initial_twist_grid(problem: _Problem, p: npt.NDArray[np.float64]) -> float:
    """The initial twist (rad) of lowest cost on a grid of 61 values spanning one static
    torque around the torque balance, the other parameters held at ``p``."""
    log = problem.log
    torque0 = float(np.median(log.column("bit_torque_nm")[:5]))
    balance = (torque0 - p[P_C] * (log.column("top_speed_rad_s")[0] - problem.speed0)) / p[P_K]
    span = problem.twist_scale(p)
    best = (math.inf, balance)
    for x0 in balance + span * np.linspace(-1.0, 1.0, 61):
        r = problem.residuals(problem.pack(p, float(x0)))
        cost = float(r @ r)
        if cost < best[0]:
            best = (cost, float(x0))
    return best[1]


JACOBIAN_STEP: Final = 1e-3
"""Central-difference step of the fit's Jacobian, in log-parameter units (0.1 %). A step of
1 % reached a lower cost on logs of the fit's own simulator but recovered the lab rig's
inertia and stiffness less well (one seed: -4.6 % and -9 % against -0.1 % and -2.7 %)."""


class _Residuals(Protocol):
    """A least-squares problem: the residual vector of a parameter vector."""

    def residuals(self, theta: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...


def _jacobian(
    problem: _Residuals, theta: npt.NDArray[np.float64], step: float = JACOBIAN_STEP
) -> npt.NDArray[np.float64]:
    columns = []
    for i in range(theta.size):
        hi = theta.copy()
        lo = theta.copy()
        hi[i] += step
        lo[i] -= step
        columns.append((problem.residuals(hi) - problem.residuals(lo)) / (2 * step))
    return np.column_stack(columns)


def _levenberg_marquardt(
    problem: _Residuals,
    theta: npt.NDArray[np.float64],
    max_iterations: int = 60,
    max_log_step: float = 4.0,
) -> tuple[npt.NDArray[np.float64], float, int]:
    """Minimise the sum of squared residuals from ``theta``, each parameter kept within
    ``max_log_step`` of its start (log space); returns (theta, cost, iterations)."""
    r = problem.residuals(theta)
    cost = float(r @ r)
    low, high = theta - max_log_step, theta + max_log_step
    damping = 1e-2
    iteration = 0
    while iteration < max_iterations:
        iteration += 1
        jac = _jacobian(problem, theta)
        g = jac.T @ r
        h = jac.T @ jac
        improved = False
        for _ in range(12):
            step = np.linalg.solve(h + damping * np.diag(np.diag(h) + 1e-12), -g)
            step = np.clip(step, -1.0, 1.0)
            trial = np.clip(theta + step, low, high)
            r_trial = problem.residuals(trial)
            cost_trial = float(r_trial @ r_trial)
            if cost_trial < cost:
                improved = True
                relative = (cost - cost_trial) / max(cost, 1e-300)
                theta, r, cost = trial, r_trial, cost_trial
                damping = max(damping / 3, 1e-9)
                break
            damping *= 4
        if not improved or relative < 1e-7:
            break
    return theta, cost, iteration


def _effective_fraction(r: npt.NDArray[np.float64]) -> float:
    """``n_eff / n`` of a residual series from its autocorrelation (sum up to the first
    negative lag), in (0, 1]."""
    r = r - r.mean()
    if not np.any(r):
        return 1.0
    n = r.size
    spectrum = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    acf /= acf[0]
    total = 0.0
    for lag in range(1, min(n, 2000)):
        if acf[lag] <= 0:
            break
        total += acf[lag]
    return 1.0 / (1.0 + 2.0 * total)


@dataclass
class FamilyFit:
    """The fit of one friction family on a window."""

    family: str
    p: npt.NDArray[np.float64]
    twist0: float
    cost: float
    n: int
    n_eff: float
    free: list[str]
    relative_std: dict[str, float]
    correlations: dict[str, tuple[str, float]]
    fixed: dict[str, str]
    bic: float
    iterations: int
    singular_values: list[float] = field(default_factory=list)


def _moderate(
    p: npt.NDArray[np.float64], log: MeasuredLog, uses_wob: bool
) -> npt.NDArray[np.float64]:
    """``p`` with damping terms near 0 raised to moderate starting values (a 2 % damping
    ratio; a viscous friction of 5 % of the sliding torque at the mean slip speed), so that
    the fit can move them: a term started at 0 has no gradient in log space."""
    q = p.copy()
    q[P_C] = max(q[P_C], 0.04 * math.sqrt(q[P_K] * q[P_J]))
    scale = float(np.mean(log.column("wob_n"))) if uses_wob else 1.0
    speed = float(np.mean(np.abs(log.column("bit_speed_rad_s")))) or 1.0
    q[P_CV] = max(q[P_CV], 0.05 * q[P_A0] * scale / speed)
    return q


def _fit_family(
    log: MeasuredLog,
    family: str,
    uses_wob: bool,
    weights: npt.NDArray[np.float64],
    starts_p: list[tuple[npt.NDArray[np.float64], float]],
    direct: npt.NDArray[np.float64],
    user_fixed: dict[str, float],
    balance: MomentumBalance | None = None,
    refined: int = STARTS_REFINED,
    screen: bool = True,
) -> FamilyFit:
    bit = log.column("bit_speed_rad_s")
    torque = log.column("bit_torque_nm")
    scales = (float(np.std(bit)) or 1.0, float(np.std(torque)) or 1.0)
    names = list(FAMILY_PARAMETERS[family]) + ["initial_twist"]
    fixed: dict[str, str] = {}
    held: dict[int, float] = {}
    for name, value in user_fixed.items():
        held[MODEL_PARAMETERS[name][0]] = value
        fixed[name] = f"fixed at {value:.6g} by the user"
    candidates = []
    for p_start, twist_start in starts_p:
        q = _moderate(p_start, log, uses_wob)
        for index, value in held.items():
            q[index] = value
        candidates.append((q, twist_start))
    p, start_twist0 = candidates[0]
    if balance is not None:  # its rows left out where the bit speed is
        weights = np.concatenate([weights, weights[: bit.size]])
    problem = _Problem(
        log, family, uses_wob, [n for n in names if n not in fixed], p.copy(),
        weights, scales, _speed0(bit, stuck_threshold(bit)), 1, start_twist0, None, balance,
    )  # fmt: skip
    iterations = 0
    free_full = list(problem.free)
    while True:
        tried = []
        free_shooting = [n for n in free_full if n != "initial_twist"]
        shooting = stuck_segments(log)
        # Continuation: one-cycle segments first (a smoother cost, each prediction short),
        # then the two-cycle segments from their optimum.
        short = stuck_segments(log, 1) if shooting is not None else None
        problem.segments = short
        if shooting is not None:
            problem.free = free_shooting
        for source, (q, twist_q) in enumerate(candidates):
            problem.fixed_p = q.copy()
            theta0 = problem.pack(q, twist_q)
            variants = [theta0]
            if family == "memory" and "memory_time" in problem.free:
                i = problem.free.index("memory_time")
                for tau in MEMORY_TIMES_S:
                    th = theta0.copy()
                    th[i] = math.log(tau)
                    variants.append(th)
            for th in variants:
                problem.substeps = substeps_for(problem.unpack(th)[0], log.sample_period_s)
                r = problem.residuals(th)
                tried.append((float(r @ r), source, q.copy(), th))
        tried.sort(key=lambda item: item[0])
        # The best start of every source (the direct estimates, the simpler family's optimum)
        # is refined, then the next best up to STARTS_REFINED: a start of low initial cost
        # from one source can lie in a poorer basin than the other source's best.
        firsts = [next(item for item in tried if item[1] == k) for k in range(len(candidates))]
        first_ids = {id(item) for item in firsts}
        chosen_starts = firsts + [item for item in tried if id(item) not in first_ids]
        best_run = None
        for _, _, q, th in chosen_starts[: max(refined, len(firsts))]:
            problem.fixed_p = q
            problem.free = free_shooting if shooting is not None else free_full
            if short is not None:
                problem.segments = short
                problem.substeps = substeps_for(problem.unpack(th)[0], log.sample_period_s)
                th, _, it = _levenberg_marquardt(problem, th)
                iterations += it
            problem.segments = shooting
            problem.substeps = substeps_for(problem.unpack(th)[0], log.sample_period_s)
            theta_run, cost_run, it = _levenberg_marquardt(problem, th)
            iterations += it
            if best_run is None or cost_run < best_run[0]:
                best_run = (cost_run, q, theta_run)
        # The Laplace covariance and the BIC are those of the stage that fitted (multiple
        # shooting when the window stick-slips); the initial twist of the whole window is
        # then the best one on a grid, for the figures and the plant file.
        assert best_run is not None
        _, problem.fixed_p, theta = best_run
        p, start_twist0 = problem.unpack(theta)
        problem.substeps = substeps_for(p, log.sample_period_s)
        theta = problem.pack(p, start_twist0)
        r = problem.residuals(theta)
        cost = float(r @ r)
        jac = _jacobian(problem, theta)
        used = weights > 0
        n = int(used.sum())
        fraction = _effective_fraction(r[used])
        n_eff = max(n * fraction, len(problem.free) + 2.0)
        s2 = cost / max(n - len(problem.free), 1)
        info = jac.T @ jac
        singular = np.linalg.svd(jac, compute_uv=False)
        ridge = 1e-10 * max(float(np.trace(info)), 1e-300) / info.shape[0]
        cov = np.linalg.inv(info + ridge * np.eye(info.shape[0])) * s2 / fraction
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        rel = {}
        corr = {}
        for i, name in enumerate(problem.free):
            if name == "initial_twist":
                continue
            if name == "sliding_friction":
                ratio = p[P_A0] / p[P_AA]
                rel[name] = float(std[i] * (1 - ratio))
            else:
                rel[name] = float(std[i])
            row = cov[i] / np.maximum(std * std[i], 1e-300)
            row[i] = 0.0
            j = int(np.argmax(np.abs(row)))
            corr[name] = (problem.free[j], float(row[j]))
        worst = max(rel, key=lambda k: rel[k] if math.isfinite(rel[k]) else math.inf, default=None)
        if (
            not screen
            or worst is None
            or (math.isfinite(rel[worst]) and rel[worst] <= MAX_RELATIVE_STD)
        ):
            break
        if len(rel) == 1:
            raise ValueError(
                f"the window identifies no parameter of the {family} family (the last one, "
                f"{worst}, has relative std {rel[worst]:.2g}): choose a window with stick-slip "
                "cycles, or hold parameters with --fix"
            )
        # Not identified: fix it at its direct estimate (or 0 for a damping term) and refit.
        index = MODEL_PARAMETERS[worst][0]
        partner, rho = corr[worst]
        if worst in ("damping", "viscous_friction"):
            value = 0.0
            how = "fixed at 0"
        elif worst == "memory_time":
            value = p[index]
            how = f"fixed at {value:.3g} s (its fitted value; the data barely depend on it)"
        else:
            value = direct[index]
            how = f"fixed at its direct estimate {value:.6g}"
        fixed[worst] = (
            f"not identifiable from this window (relative std {rel[worst]:.2g}, correlation "
            f"{rho:+.2f} with {partner}): {how}"
        )
        p[index] = value
        if worst == "static_friction" and p[P_A0] > value:
            p[P_A0] = value
        held[index] = value
        free_full = [n for n in free_full if n != worst]
        candidates = [(p.copy(), start_twist0)]
    if problem.segments is not None:
        # The parameters stay those of the multiple shooting (a last fit of one simulation
        # of the whole window, even within 16 % of them, matched the fitted window better
        # and the held-out windows no better); only the window's initial twist is set here.
        problem.segments = None
        problem.free = free_full
        problem.fixed_p = p.copy()
        problem.substeps = substeps_for(p, log.sample_period_s)
        start_twist0 = _initial_twist_grid(problem, p)
    k = len(problem.free)
    bic = n_eff * math.log(cost / n) + k * math.log(n_eff)
    return FamilyFit(
        family, p, start_twist0, cost, n, n_eff, list(problem.free), rel, corr, fixed, bic,
        iterations, [float(v) for v in singular],
    )  # fmt: skip


BOOTSTRAP_REPLICATES: Final = 100
"""Replicates of the residual block bootstrap of the chosen family's parameters."""
BOOTSTRAP_ITERATIONS: Final = 8
"""Refit iterations of one bootstrap replicate."""
BOOTSTRAP_SEED: Final = 20_240_601
"""Seed of the bootstrap's resampling (same log, same intervals)."""


@dataclass
class Bootstrap:
    """The uncertainty of one fit's free parameters: per parameter the relative standard
    deviation (of its logarithm) and the 95 % interval. ``method`` is ``"cycle_jackknife"``
    (:func:`cycle_jackknife`: ``replicates`` refits, one per left-out group of cycles) or
    ``"residual_bootstrap"`` (:func:`bootstrap`: ``replicates`` resamples in blocks of
    ``block_samples``)."""

    relative_std: dict[str, float]
    interval_95: dict[str, tuple[float, float]]
    replicates: int
    block_samples: int
    method: str = "residual_bootstrap"

    def description(self) -> str:
        """One sentence saying how the intervals were made, for the report and the file."""
        if self.method == "cycle_jackknife":
            return (
                f"a jackknife over whole stick-slip cycles ({self.replicates} whole refits, "
                "each leaving out one group of consecutive measured cycles; Student-t "
                f"intervals with {self.replicates - 1} degrees of freedom)"
            )
        return (
            f"a residual block bootstrap ({self.replicates} replicates, blocks of "
            f"{self.block_samples} samples: the fitted residuals resampled onto the fitted "
            "simulation and the parameters refitted)"
        )


STUDENT_T_975: Final = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
)  # fmt: skip
"""The 97.5 % quantile of Student's t with 1 to 20 degrees of freedom."""


def student_t_975(dof: int) -> float:
    """The 97.5 % quantile of Student's t with ``dof`` >= 1 degrees of freedom (a table to
    20, then the expansion ``z + (z^3 + z) / (4 dof) + (5 z^5 + 16 z^3 + 3 z) / (96 dof^2)``,
    within 1e-3 of the exact quantile)."""
    if dof < 1:
        raise ValueError(f"dof = {dof}: allowed >= 1")
    if dof <= len(STUDENT_T_975):
        return STUDENT_T_975[dof - 1]
    z = 1.959964
    return z + (z**3 + z) / (4 * dof) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * dof**2)


WEAKLY_PINNED: Final = "weakly pinned: the refits without some cycles move it far"
"""Note of an identified parameter whose resampled spread exceeds :data:`MAX_RELATIVE_STD`
(the Laplace screen passed it, the cycles of the window do not agree on it)."""
JACKKNIFE_MIN_CYCLES: Final = 4
"""Fewest measured stick-slip cycles in the window for the cycle jackknife (with fewer the
residual block bootstrap gives the intervals)."""
JACKKNIFE_MAX_GROUPS: Final = 6
"""Most groups of the cycle jackknife: a window of more cycles is cut into this many groups
of consecutive whole cycles, one refit per group left out (each refit is a whole fit)."""


def cycle_labels(log: MeasuredLog) -> npt.NDArray[np.intp] | None:
    """The jackknife group of every sample, ``(n,)``: stick-slip cycles run from the middle of
    one measured stuck run to the middle of the next (the samples before the first belong to
    the first), and consecutive cycles form at most :data:`JACKKNIFE_MAX_GROUPS` groups of
    nearly equal counts; None with fewer than :data:`JACKKNIFE_MIN_CYCLES` cycles."""
    runs = stuck_segments(log, 1)
    if runs is None or len(runs) < JACKKNIFE_MIN_CYCLES:
        return None
    groups = min(len(runs), JACKKNIFE_MAX_GROUPS)
    labels = np.zeros(log.time_s.size, dtype=np.intp)
    for cycle, (a, b, *_) in enumerate(runs):
        labels[a:b] = cycle * groups // len(runs)
    return labels


def cycle_jackknife(
    fit: FamilyFit,
    labels: npt.NDArray[np.intp],
    refit: Callable[[npt.NDArray[np.float64], dict[str, float]], FamilyFit],
    weights: npt.NDArray[np.float64],
) -> Bootstrap:
    """Jackknife over whole stick-slip cycles of the whole fit of one family.

    For each group of measured cycles (``labels``, :func:`cycle_labels`) the residuals of
    those samples (bit speed, torque on bit, momentum balance) are left out (``weights`` zeroed)
    and the family is fitted again by ``refit(weights, held)`` -- from the direct
    estimates, by the same multiple shooting, the parameters the fit held kept at their
    values and no further one held -- so that the
    spread of the refits contains everything that moves the estimate when the data change:
    the noise, the model's misfit that differs from cycle to cycle, and where the
    optimiser stops on a stick-slip cost that is rough at the scale of one cycle's phase.
    Cycles are the independent units of a stick-slip log: each prediction starts afresh
    from a measured stuck state. The variance of each log-parameter is ``(G - 1) / G`` times
    the sum of squares of the ``G`` refits about their mean, and the interval is
    ``log(theta) +- t_{G-1} se`` about the full fit. It is conditional on the held
    parameters.
    """
    groups = int(labels.max()) + 1
    rows = np.tile(labels, weights.size // labels.size + 1)[: weights.size]
    held = {name: float(fit.p[MODEL_PARAMETERS[name][0]]) for name in fit.fixed}
    draws = [refit(np.where(rows == g, 0.0, weights), held) for g in range(groups)]
    quantile = student_t_975(groups - 1)
    rel: dict[str, float] = {}
    interval: dict[str, tuple[float, float]] = {}
    for name in fit.free:
        if name == "initial_twist":
            continue
        index = MODEL_PARAMETERS[name][0]
        centre = math.log(fit.p[index])
        logs = np.log([max(d.p[index], 1e-300) for d in draws])
        se = math.sqrt((groups - 1) / groups * float(np.sum((logs - logs.mean()) ** 2)))
        rel[name] = se
        half = min(quantile * se, 300.0)  # beyond e^300 the interval says: anything
        interval[name] = (math.exp(centre - half), math.exp(centre + half))
    return Bootstrap(rel, interval, groups, 0, "cycle_jackknife")


def _shooting_problem(
    log: MeasuredLog,
    fit: FamilyFit,
    uses_wob: bool,
    weights: npt.NDArray[np.float64],
    balance: MomentumBalance | None,
) -> _Problem:
    """The residuals the fit of ``fit`` minimised (multiple shooting when the window
    stick-slips, else the whole window with its initial twist), at its free parameters."""
    bit = log.column("bit_speed_rad_s")
    torque = log.column("bit_torque_nm")
    scales = (float(np.std(bit)) or 1.0, float(np.std(torque)) or 1.0)
    segments = stuck_segments(log)
    free = [n for n in fit.free if n != "initial_twist"] if segments is not None else fit.free
    if balance is not None:
        weights = np.concatenate([weights, weights[: bit.size]])
    return _Problem(
        log, fit.family, uses_wob, list(free), fit.p.copy(), weights, scales,
        _speed0(bit, stuck_threshold(bit)), substeps_for(fit.p, log.sample_period_s),
        fit.twist0, segments, balance,
    )  # fmt: skip


def bootstrap(
    problem: _Problem,
    replicates: int = BOOTSTRAP_REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> Bootstrap:
    """Residual block bootstrap at the optimum of ``problem``.

    The fitted residuals of the bit speed and the torque on bit (on the window's clock) are
    resampled in blocks of one correlation length (``n / n_eff`` samples, the same blocks for
    both, so that their correlations in time and between them are kept) and added to the
    fitted simulation: a new measured window, on which everything the fit takes from the
    data is taken again (the segments' starting states, the momentum balance), and the
    parameters are refitted (a Gauss-Newton chord iteration with the optimum's Jacobian,
    every residual a full simulation). The spread of the refitted parameters is their
    uncertainty, the model's misfit included; it is conditional on the held parameters.
    """
    theta = problem.pack(problem.fixed_p, problem.twist0_fixed)
    base = problem.residuals(theta)
    log = problem.log
    n = log.time_s.size
    used = problem.weights[: 2 * n] > 0
    fraction = _effective_fraction(base[: 2 * n][used])
    block = int(min(max(1, round(1.0 / fraction)), max(1, n // 4)))
    jac = _jacobian(problem, theta)
    info = jac.T @ jac
    info += 1e-9 * max(float(np.trace(info)), 1e-300) / info.shape[0] * np.eye(info.shape[0])
    factor = np.linalg.cholesky(info)

    def solve(g: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.asarray(np.clip(-np.linalg.solve(factor.T, np.linalg.solve(factor, g)), -1, 1))

    names = ("bit_speed_rad_s", "bit_torque_nm")
    fitted = [
        log.column(name) - np.where(used[k * n : (k + 1) * n], base[k * n : (k + 1) * n], 0.0)
        * problem.scales[k]
        for k, name in enumerate(names)
    ]  # fmt: skip
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(replicates):
        starts = rng.integers(0, n - block + 1, size=-(-n // block))
        index = (starts[:, None] + np.arange(block)[None, :]).ravel()[:n]
        columns = dict(log.columns)
        for k, name in enumerate(names):
            noise = np.where(used[k * n : (k + 1) * n], base[k * n : (k + 1) * n], 0.0)[index]
            columns[name] = fitted[k] + noise * problem.scales[k]
        data = MeasuredLog(log.time_s, columns, log.source)
        segments = stuck_segments(data) if problem.segments is not None else None
        replica = dataclasses.replace(
            problem, log=data, segments=segments, _angle=None,
            balance=None if problem.balance is None else MomentumBalance.of(data),
        )  # fmt: skip
        if segments is not None and len(segments) != len(problem.segments or []):
            replica = dataclasses.replace(replica, segments=problem.segments)
        # The first step is the linearised refit (always taken: the cost of stick-slip is not
        # smooth at the scale of one replicate's noise, and a rejected step would leave the
        # replicate at the optimum and the interval too narrow); the chord iteration then
        # moves only downhill.
        th = theta + solve(jac.T @ replica.residuals(theta))
        r = replica.residuals(th)
        cost = float(r @ r)
        for _ in range(BOOTSTRAP_ITERATIONS):
            step = solve(jac.T @ r)
            for _ in range(4):
                trial = th + step
                r_trial = replica.residuals(trial)
                cost_trial = float(r_trial @ r_trial)
                if cost_trial < cost:
                    break
                step = 0.5 * step
            else:
                break
            converged = (cost - cost_trial) < 1e-6 * cost
            th, r, cost = trial, r_trial, cost_trial
            if converged:
                break
        draws.append(th)
    samples = np.array(draws)
    rel: dict[str, float] = {}
    interval: dict[str, tuple[float, float]] = {}
    for name in problem.free:
        if name == "initial_twist":
            continue
        values = np.array([_value_of(problem, th, name) for th in samples])
        rel[name] = float(np.std(np.log(values)))
        low, high = np.percentile(values, [2.5, 97.5])
        interval[name] = (float(low), float(high))
    return Bootstrap(rel, interval, replicates, block)


def _value_of(problem: _Problem, theta: npt.NDArray[np.float64], name: str) -> float:
    return float(problem.unpack(theta)[0][MODEL_PARAMETERS[name][0]])


@dataclass
class FitResult:
    """A calibration: the chosen plant, every family's fit, the window's defects."""

    plant: CalibratedPlant
    fits: dict[str, FamilyFit]
    defects: list[Defect]
    excluded_samples: int
    wall_s: float
    top_drive: TopDriveFit | None = None
    bootstrap: Bootstrap | None = None
    string: StringFit | None = None


def fit_weights(window: MeasuredLog) -> tuple[npt.NDArray[np.float64], list[Defect]]:
    """Residual weights of a window (1, or 0 for samples of a spike or a flat line of the
    fitted columns: they are left out of the residual, the data are not changed) and the
    window's defects."""
    defects = find_defects(window)
    n = window.time_s.size
    weights = np.ones(2 * n)
    for offset, name in ((0, "bit_speed_rad_s"), (n, "bit_torque_nm")):
        mask = spike_mask(window.column(name))
        for d in defects:
            if d.column == name and d.kind == "flat_line":
                mask[d.rows[0] - 1 : d.rows[1]] = True
        weights[offset : offset + n][mask] = 0.0
    return weights, defects


def calibrate(
    log: MeasuredLog,
    window_s: tuple[float, float],
    families: tuple[str, ...] = FAMILIES,
    use_wob: bool = True,
    fixed: dict[str, float] | None = None,
) -> FitResult:
    """Fit every family in ``families`` on the window and keep the one of lowest BIC.

    Args:
        log: The measured log; needs ``bit_speed_rad_s`` and ``bit_torque_nm``.
        window_s: ``(start, end)`` of the fitted window, s.
        families: Friction families to fit (:data:`drill_env.bit_model.FAMILIES`).
        use_wob: Scale the friction with ``wob_n`` when the log has it.
        fixed: Parameters held at given values (name -> value in its unit).
    """
    started = time.perf_counter()
    for name in ("bit_speed_rad_s", "bit_torque_nm"):
        if not log.has(name):
            raise ValueError(
                f"the log has no column {shown(name)}: calibrate fits the bit speed and the torque "
                "on bit, and needs both"
            )
    user_fixed = {
        name: check_parameter(name, value, f"fixed {name}") for name, value in (fixed or {}).items()
    }
    window = log.window(*window_s)
    uses_wob = use_wob and window.has("wob_n")
    if uses_wob and not np.all(window.column("wob_n") > 0):
        raise ValueError("column 'wob_n' has values <= 0 in the window: allowed > 0 N")
    weights, defects = fit_weights(window)
    direct, twist0 = initial_estimates(window, uses_wob)
    balance = MomentumBalance.of(window) if _balance_estimates(window)[4] else None
    fits: dict[str, FamilyFit] = {}
    family_starts: dict[str, list[tuple[npt.NDArray[np.float64], float]]] = {}
    previous: tuple[npt.NDArray[np.float64], float] | None = None
    for family in FAMILIES:
        if family not in families:
            continue
        fam_fixed = {k: v for k, v in user_fixed.items() if k in FAMILY_PARAMETERS[family]}
        starts = [(direct.copy(), twist0)]
        if previous is not None:
            starts.append(previous)
        family_starts[family] = starts
        fit = _fit_family(window, family, uses_wob, weights, starts, direct, fam_fixed, balance)
        fits[family] = fit
        previous = (fit.p.copy(), fit.twist0)
    # One effective sample size for every family (the simplest family's), so that the BIC
    # compares costs on one footing.
    n_eff = next(iter(fits.values())).n_eff
    for f in fits.values():
        f.n_eff = n_eff
        f.bic = n_eff * math.log(f.cost / f.n) + len(f.free) * math.log(n_eff)
    chosen = min(fits.values(), key=lambda f: f.bic)
    # The uncertainty of the chosen family's parameters: the delete-one-cycle jackknife of
    # its whole fit when the window has enough stick-slip cycles, else a residual block
    # bootstrap (the Laplace screen of the fit decided which parameters are identified).
    labels = cycle_labels(window)
    if labels is None:
        boot = bootstrap(_shooting_problem(window, chosen, uses_wob, weights, balance))
    else:

        def refit(w: npt.NDArray[np.float64], held: dict[str, float]) -> FamilyFit:
            # From the direct estimates (the simpler family's optimum would carry the full
            # window's data into the refit), its best start refined.
            starts = [(q.copy(), x) for q, x in family_starts[chosen.family][:1]]
            return _fit_family(
                window, chosen.family, uses_wob, w, starts, direct, held, balance, refined=1,
                screen=False,
            )  # fmt: skip

        boot = cycle_jackknife(chosen, labels, refit, weights)
    plant = _plant_of(chosen, window, uses_wob, window_s, log.source, fits, defects, weights, boot)
    top = identify_top_drive(window, float(chosen.p[P_J]))
    string = None
    if top.values is not None:
        top_values = {**top.values, "pi_law_r2": top.loop_r2, "momentum_balance_r2": top.balance_r2}
        loop = (
            top.values["speed_gain_nm_s_rad"], top.values["integral_gain_nm_rad"],
            top.values["reference_speed_rad_s"],
        )  # fmt: skip
        string = identify_string(
            window, (float(chosen.p[P_K]), float(chosen.p[P_C])), loop, top.values["inertia_kg_m2"]
        )
        if string.chosen == "pipe":
            values = string.models["pipe"].values
            top_values["inertia_kg_m2"] = values["top_inertia_kg_m2"]
            top_values.update({key: values[key] for key in STRING_KEYS})
        plant = dataclasses.replace(plant, top_drive=top_values)
    return FitResult(
        plant, fits, defects, int((weights == 0).sum()), time.perf_counter() - started, top,
        boot, string,
    )  # fmt: skip


def _hold_value(name: str, p: npt.NDArray[np.float64], direct: npt.NDArray[np.float64]) -> float:
    """Where a parameter the window does not identify is held: damping terms at 0, the
    memory time at its fitted value, the others at their direct estimate."""
    index = MODEL_PARAMETERS[name][0]
    if name in ("damping", "viscous_friction"):
        return 0.0
    if name == "memory_time":
        return float(p[index])
    return float(direct[index])


def _plant_of(
    fit: FamilyFit,
    window: MeasuredLog,
    uses_wob: bool,
    window_s: tuple[float, float],
    source: str,
    fits: dict[str, FamilyFit],
    defects: list[Defect],
    weights: npt.NDArray[np.float64],
    boot: Bootstrap | None = None,
) -> CalibratedPlant:
    parameters = {}
    for name in FAMILY_PARAMETERS[fit.family]:
        value = float(fit.p[MODEL_PARAMETERS[name][0]])
        if name in fit.fixed:
            parameters[name] = FittedParameter(
                value, parameter_unit(name, uses_wob), False, None, fit.fixed[name]
            )
        elif boot is not None and name in boot.relative_std:
            spread = boot.relative_std[name]
            weak = (
                f"; {WEAKLY_PINNED} (relative std {spread:.2g} above {MAX_RELATIVE_STD:.0%}): "
                "read the interval, not the value"
                if spread > MAX_RELATIVE_STD
                else ""
            )
            parameters[name] = FittedParameter(
                value, parameter_unit(name, uses_wob), True, spread,
                f"fitted (output error on bit speed and torque on bit); uncertainty: "
                f"{boot.description()}; Laplace relative std "
                f"{fit.relative_std.get(name, math.nan):.2g}{weak}",
                boot.interval_95[name],
            )  # fmt: skip
        else:
            parameters[name] = FittedParameter(
                value, parameter_unit(name, uses_wob), True, fit.relative_std.get(name),
                "fitted (output error on bit speed and torque on bit); uncertainty: Laplace",
            )  # fmt: skip
        low, high = PARAMETER_RANGES[name]
        if not low <= value <= high:  # an unpinned value that ran off: the plant keeps the end
            held = parameters[name]
            parameters[name] = dataclasses.replace(
                held,
                value=min(max(value, low), high),
                note=f"{held.note}; the fit's {value:.3g} held at the end of the allowed range "
                f"{parameter_range_text(name)}",
            )
    bit = window.column("bit_speed_rad_s")
    # The noise of the bit-speed sensor: the robust spread of the second differences (white
    # noise of std s gives std s sqrt(6); a smooth signal's trend cancels).
    second = np.diff(bit, 2)
    noise = 1.4826 * float(np.median(np.abs(second - np.median(second)))) / math.sqrt(6)
    operating = {
        "mean_top_speed_rad_s": float(np.mean(window.column("top_speed_rad_s"))),
        "mean_bit_speed_rad_s": float(np.mean(bit)),
        "bit_speed_noise_rad_s": noise,
        "mean_bit_torque_nm": float(np.mean(window.column("bit_torque_nm"))),
    }
    if uses_wob:
        operating["mean_wob_n"] = float(np.mean(window.column("wob_n")))
    return CalibratedPlant(
        family=fit.family,
        uses_wob=uses_wob,
        parameters=parameters,
        initial_twist_rad=float(fit.twist0),
        window_s=(float(window_s[0]), float(window_s[1])),
        log=source,
        fit={
            "method": "Levenberg-Marquardt output error, residuals of bit speed and torque on "
            "bit each divided by its standard deviation in the window",
            "selection": "lowest BIC with the effective sample size of the residuals",
            "families": {
                name: {
                    "bic": f.bic,
                    "normalised_rms": math.sqrt(f.cost / f.n),
                    "free_parameters": len(f.free),
                    "n_effective": f.n_eff,
                }
                for name, f in fits.items()
            },
            "samples": int(window.time_s.size),
            "excluded_residuals": int((weights == 0).sum()),
            "defects_in_window": len(defects),
            "max_relative_std": MAX_RELATIVE_STD,
        },
        operating_point=operating,
    )


def simulate_plant(
    plant: CalibratedPlant, log: MeasuredLog, twist0: float | None = None
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Drive ``plant`` with the log's top-drive speed; returns the bit speed (rad/s) and the
    torque on bit (N m) on the log's clock.

    The initial state: the measured bit speed (0 below the stuck threshold) and, unless given,
    the twist that balances the measured torque on bit (or the plant's fitted twist when the
    log has no torque on bit).
    """
    p = plant.model_vector()
    uses_wob = plant.uses_wob
    if uses_wob and not log.has("wob_n"):
        raise ValueError("the plant's friction scales with WOB but the log has no column 'wob_n'")
    speed0 = 0.0
    if log.has("bit_speed_rad_s"):
        bit = log.column("bit_speed_rad_s")
        speed0 = _speed0(bit, stuck_threshold(bit))
    wob = wob_input(log) if uses_wob else None
    if twist0 is None:
        twist0 = initial_twist(plant, log, speed0)
    speed, torque, _ = simulate_bit(
        log.time_s, log.column("top_speed_rad_s"), p, plant.family, twist0, speed0, wob
    )
    return speed, torque


INITIAL_STATE_FRACTION: Final = 0.25
"""Share of a replayed window, from its start, on which its initial twist is estimated."""


def initial_twist(plant: CalibratedPlant, log: MeasuredLog, speed0: float) -> float:
    """The string's twist at the start of a replayed log, rad: the value that best matches
    the measured bit speed and torque on bit over the first :data:`INITIAL_STATE_FRACTION` of
    the log (a grid of 61 values within one static torque of the torque balance), or the
    torque balance alone when the log lacks either column. Only this initial state is
    estimated from a replayed window; the plant's parameters are not touched.
    """
    p = plant.model_vector()
    top0 = float(log.column("top_speed_rad_s")[0])
    if not log.has("bit_torque_nm"):
        return plant.initial_twist_rad
    torque0 = float(np.median(log.column("bit_torque_nm")[:5]))
    balance = (torque0 - p[P_C] * (top0 - speed0)) / p[P_K]
    if not log.has("bit_speed_rad_s"):
        return balance
    n = max(3, int(INITIAL_STATE_FRACTION * log.time_s.size))
    head = log.time_s[:n]
    top = log.column("top_speed_rad_s")[:n]
    bit = log.column("bit_speed_rad_s")[:n]
    torque = log.column("bit_torque_nm")[:n]
    wob = wob_input(log)[:n] if plant.uses_wob else None
    span = p[P_AA] * (float(np.mean(wob)) if wob is not None else 1.0) / p[P_K]
    scales = (float(np.std(bit)) or 1.0, float(np.std(torque)) or 1.0)
    best = (math.inf, balance)
    for x0 in balance + span * np.linspace(-1.0, 1.0, 61):
        s, q, _ = simulate_bit(head, top, p, plant.family, float(x0), speed0, wob)
        cost = float(np.mean(((s - bit) / scales[0]) ** 2 + ((q - torque) / scales[1]) ** 2))
        if cost < best[0]:
            best = (cost, float(x0))
    return best[1]


def _cycle_starts(speed: npt.NDArray[np.float64], low: float, high: float) -> npt.NDArray[np.intp]:
    """Indices where the speed rises through ``high`` after having been below ``low``."""
    starts = []
    armed = False
    for i, v in enumerate(speed):
        if v < low:
            armed = True
        elif armed and v > high:
            starts.append(i)
            armed = False
    return np.asarray(starts, dtype=np.intp)


def features(
    time_s: npt.NDArray[np.float64],
    bit_speed: npt.NDArray[np.float64],
    bit_torque: npt.NDArray[np.float64],
    threshold: float,
) -> dict[str, float]:
    """Stick-slip features of one window (NaN when there are fewer than two cycles).

    * ``period_fft_s``: 1 / the dominant frequency of the bit speed (parabolic peak of the
      spectrum of the mean-removed speed, zero-padded 8 times).
    * ``period_cycles_s``: mean time between cycle starts (the speed rising through
      ``2 threshold`` after being below ``threshold``, rad/s).
    * ``bit_speed_p2p_rad_s``, ``bit_torque_p2p_nm``: mean over cycles of max - min.
    * ``bit_torque_mean_nm``: mean torque on bit.
    * ``stuck_fraction``: fraction of samples with ``|bit speed| < threshold``.
    """
    out: dict[str, float] = dict.fromkeys(FEATURE_KEYS, math.nan)
    out["bit_torque_mean_nm"] = float(np.mean(bit_torque))
    out["stuck_fraction"] = float(np.mean(np.abs(bit_speed) < threshold))
    dt = float(np.median(np.diff(time_s)))
    x = bit_speed - bit_speed.mean()
    spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size), 8 * x.size))
    freqs = np.fft.rfftfreq(8 * x.size, dt)
    band = freqs > 1.5 / (time_s[-1] - time_s[0])
    if band.any() and np.any(x):
        i = int(np.flatnonzero(band)[np.argmax(spectrum[band])])
        if 0 < i < spectrum.size - 1:
            a, b, c = spectrum[i - 1], spectrum[i], spectrum[i + 1]
            shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
            f = freqs[i] + shift * (freqs[1] - freqs[0])
            out["period_fft_s"] = 1.0 / f if f > 0 else math.nan
    starts = _cycle_starts(bit_speed, threshold, 2 * threshold)
    if starts.size >= 2:
        out["period_cycles_s"] = float(np.mean(np.diff(time_s[starts])))
        speeds = [np.ptp(bit_speed[a:b]) for a, b in zip(starts[:-1], starts[1:], strict=False)]
        torques = [np.ptp(bit_torque[a:b]) for a, b in zip(starts[:-1], starts[1:], strict=False)]
        out["bit_speed_p2p_rad_s"] = float(np.mean(speeds))
        out["bit_torque_p2p_nm"] = float(np.mean(torques))
    return out


def feature_errors(measured: dict[str, float], simulated: dict[str, float]) -> dict[str, float]:
    """Relative errors of the simulated features (absolute for the stuck fraction)."""
    out: dict[str, float] = {}
    for key in FEATURE_KEYS:
        m, s = measured[key], simulated[key]
        if key == "stuck_fraction":
            out[key] = s - m
        else:
            out[key] = (s - m) / abs(m) if m else math.nan
    return out


MIN_TOP_DRIVE_R2: Final = 0.5
"""Least share of the surface torque's variance a PI speed loop must explain for the top drive
to count as identified."""


@dataclass
class TopDriveFit:
    """The top drive identified from a window's top speed and surface torque (or why not).

    ``values`` follow :data:`drill_env.bit_model.TOP_DRIVE_KEYS`; ``loop_r2`` is the share of
    the surface torque's variance that the PI law explains, ``balance_r2`` that of the
    momentum balance of the top drive and the bit."""

    values: dict[str, float] | None
    loop_r2: float = math.nan
    balance_r2: float = math.nan
    reason: str = ""


def _cumulative(t: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))))


def identify_top_drive(window: MeasuredLog, bit_inertia_kg_m2: float) -> TopDriveFit:
    """Identify the top drive of the free-running mode from the window (docs/calibration.md).

    * Its inertia ``J_t`` from the momentum balance of the top drive and the bit, integrated
      once: ``J_t (w_t - w_t(0)) + J (w_b - w_b(0)) = int(T_s - T_bit) + a + b t`` (``T_s``
      the surface torque; ``b`` absorbs a constant torque lost on the way), least squares.
    * Its PI speed loop from ``T_s = k_p (r - w_t) + k_i int(r - w_t)``, i.e. ``T_s = a_0 +
      a_1 t - k_p w_t - k_i int(w_t)`` (least squares; ``r = a_1 / k_i``).

    Returns the values, or None and the reason when the log has no surface torque or the fit
    does not describe a top drive under a PI speed loop.
    """
    if not window.has("surface_torque_nm"):
        return TopDriveFit(None, reason="the log has no surface_torque_nm column: the top "
                           "drive cannot be identified (free running needs it)")  # fmt: skip
    t = window.time_s - window.time_s[0]
    top = window.column("top_speed_rad_s")
    surface = window.column("surface_torque_nm")
    net = _cumulative(t, surface)
    if window.has("bit_torque_nm") and window.has("bit_speed_rad_s"):
        net = net - _cumulative(t, window.column("bit_torque_nm"))
        bit = window.column("bit_speed_rad_s")
        target = net - bit_inertia_kg_m2 * (bit - bit[0])
    else:
        return TopDriveFit(None, reason="the window lacks the bit speed or the torque on bit")
    a = np.column_stack([top - top[0], np.ones_like(t), t])
    # A spike of a speed is one equation far off: left out, the data unchanged.
    rows = ~(spike_mask(bit) | spike_mask(top))
    coef, *_ = np.linalg.lstsq(a[rows], target[rows], rcond=None)
    inertia = float(coef[0])
    misfit = target[rows] - a[rows] @ coef
    balance_r2 = 1.0 - float(np.var(misfit) / (np.var(target[rows]) or 1.0))
    b = np.column_stack([np.ones_like(t), t, -top, -_cumulative(t, top)])
    loop, *_ = np.linalg.lstsq(b, surface, rcond=None)
    loop_r2 = 1.0 - float(np.var(surface - b @ loop) / (np.var(surface) or 1.0))
    kp, ki = float(loop[2]), float(loop[3])
    if not (inertia > 0 and kp >= 0 and ki > 0 and loop_r2 >= MIN_TOP_DRIVE_R2):
        return TopDriveFit(
            None, loop_r2, balance_r2,
            f"the surface torque is not that of a PI speed loop on the top drive (inertia "
            f"{inertia:.4g} kg m^2, gains {kp:.4g} N m s/rad and {ki:.4g} N m/rad, PI law "
            f"explains {loop_r2:.0%} of its variance; needed: inertia > 0, gains >= 0, "
            f">= {MIN_TOP_DRIVE_R2:.0%})",
        )  # fmt: skip
    values = {
        "inertia_kg_m2": inertia,
        "speed_gain_nm_s_rad": kp,
        "integral_gain_nm_rad": ki,
        "reference_speed_rad_s": float(loop[1]) / ki,
    }
    return TopDriveFit(values, loop_r2, balance_r2)


@dataclass
class StringModelFit:
    """One model of the string above the bit side, fitted by :func:`identify_string`.

    ``values`` by name (``top_inertia_kg_m2`` and the :data:`STRING_KEYS`), ``relative_std``
    of the free ones (Laplace), ``held`` the reason of each held one, ``rms`` the top-speed
    residual divided by the measured top speed's standard deviation."""

    name: str
    values: dict[str, float]
    relative_std: dict[str, float]
    held: dict[str, str]
    rms: float
    bic: float
    free: int


@dataclass
class StringFit:
    """The evidence for a pipe inertia between the top drive and the bit side: both models'
    fits and the chosen one (``"one_inertia"`` or ``"pipe"``), or why none was made."""

    models: dict[str, StringModelFit]
    chosen: str
    reason: str = ""
    bridged_spikes: int = 0
    """Spike samples of the measured bit speed bridged in the driving signal
    (:func:`driving_bit_speed`)."""


def driving_bit_speed(window: MeasuredLog) -> tuple[npt.NDArray[np.float64], int]:
    """The measured bit speed as the fits integrate it, rad/s, and how many samples were
    bridged: the spikes of :func:`drill_env.measured_log.spike_mask` replaced by the linear
    interpolation of their neighbours. The upper string's fit and the momentum balances use
    the bit speed through its integral (the twist of the spring above the bit), so a
    one-sample spike of a sensor would add a twist that never leaves; where the bit speed is
    fitted instead, its spikes are left out of the residual (:func:`fit_weights`)."""
    bit = window.column("bit_speed_rad_s")
    spikes = spike_mask(bit)
    if not spikes.any():
        return bit, 0
    keep = ~spikes
    return np.interp(window.time_s, window.time_s[keep], bit[keep]), int(spikes.sum())


class _TopSideProblem:
    """Output error of the top speed and the surface torque of
    :func:`drill_env.bit_model.simulate_top_side` (the identified PI loop, driven by the
    measured bit speed), for :func:`_levenberg_marquardt`."""

    def __init__(
        self,
        window: MeasuredLog,
        lower: tuple[float, float],
        loop: tuple[float, float, float],
        pipe: bool,
        held: dict[int, float],
    ) -> None:
        self.time = window.time_s
        self.surface = window.column("surface_torque_nm")
        self.bit, _ = driving_bit_speed(window)
        self.top = window.column("top_speed_rad_s")
        self.top0 = float(np.median(self.top[:3]))
        self.lower = lower
        self.loop = loop
        kp, ki, reference = loop
        self.integral0 = (float(np.median(self.surface[:3])) - kp * (reference - self.top0)) / ki
        self.pipe = pipe
        self.held = held
        self.scales = (float(np.std(self.top)) or 1.0, float(np.std(self.surface)) or 1.0)
        # theta: log J_t, log d_t, twist0 k / T, [log J_p, log k_1, log c_1, twist_1 k_1 / T,
        # (w_p0 - w_t0) / std(w_t)]; T the mean surface torque.
        self.torque_scale = float(np.mean(np.abs(self.surface))) or 1.0

    def unpack(
        self, theta: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], tuple[float, float, float, float, float]]:
        th = theta.copy()
        for index, value in self.held.items():
            th[index] = value
        k, c = self.lower
        x = np.zeros(10)
        x[0], x[1], x[2], x[3] = math.exp(th[0]), math.exp(th[1]), k, c
        x[7:10] = self.loop
        twist0 = th[2] * self.torque_scale / k
        if not self.pipe:
            return x, (twist0, 0.0, 0.0, self.top0, self.integral0)
        x[4], x[5], x[6] = math.exp(th[3]), math.exp(th[4]), math.exp(th[5])
        twist_1 = th[6] * self.torque_scale / x[5]
        pipe0 = self.top0 + th[7] * self.scales[0]
        return x, (twist0, pipe0, twist_1, self.top0, self.integral0)

    def substeps(self, x: npt.NDArray[np.float64]) -> int:
        dt = float(np.median(np.diff(self.time)))
        j_top, d_top, k, c, j_pipe, k_1, c_1, kp = x[:8]
        if j_pipe > 0:
            omega = math.sqrt(k_1 * (1 / j_top + 1 / j_pipe) + k / j_pipe)
            rate = max((kp + d_top + c_1) / j_top, (c_1 + c) / j_pipe)
        else:
            omega = math.sqrt(k / j_top)
            rate = (kp + d_top + c) / j_top
        return int(max(4, math.ceil(dt * omega / 0.05), math.ceil(dt * rate / 0.2)))

    def residuals(self, theta: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        x, state0 = self.unpack(theta)
        substeps = self.substeps(x)
        if (
            substeps > MAX_TOP_SIDE_SUBSTEPS
        ):  # a mode the log cannot show: rejected, as a divergence
            return np.full(2 * self.time.size, 1e3)
        top, surface = simulate_top_side(self.time, self.bit, x, state0, substeps)
        r = np.concatenate(
            [(top - self.top) / self.scales[0], (surface - self.surface) / self.scales[1]]
        )
        return np.asarray(np.where(np.isfinite(r), r, 1e3))


MAX_TOP_SIDE_SUBSTEPS: Final = 128
"""Most integration steps per sample interval of the upper string's fit: enough to resolve
a mode (or a loop's rate) at twice the sampling frequency. A mode above the log's Nyquist
frequency cannot be identified from it, so trial values that need more steps are rejected
like a divergence instead of costing up to 40 times more per evaluation (a spike in the
measured bit speed drove a 3 s window's fit to two minutes)."""

STRING_NAMES: Final = (
    "top_inertia_kg_m2", "damping_nm_s_rad", "", "pipe_inertia_kg_m2", "pipe_stiffness_nm_rad",
    "pipe_damping_nm_s_rad",
)  # fmt: skip
"""Names of the log-parameters of :class:`_TopSideProblem` (the third is the initial twist)."""


def _fit_string_model(
    window: MeasuredLog,
    lower: tuple[float, float],
    loop: tuple[float, float, float],
    pipe: bool,
    top_inertia: float,
) -> tuple[StringModelFit, npt.NDArray[np.float64]]:
    """Fit one model of the string above the bit side (several starts, Levenberg-Marquardt,
    the damping terms the Laplace screen cannot identify held near 0 and the rest refitted);
    returns the fit and its top-speed residual."""
    k, c = lower
    surface = window.column("surface_torque_nm")
    torque_scale = float(np.mean(np.abs(surface))) or 1.0
    twist_start = float(np.median(surface[:3])) / torque_scale
    # The top drive's damping to ground starts at 1 % of the mean torque at the mean speed.
    mean_speed = max(float(np.mean(np.abs(window.column("top_speed_rad_s")))), 1e-9)
    d_start = math.log(max(0.01 * torque_scale / mean_speed, 1e-12))
    starts = []
    if pipe:
        for share in (0.25, 0.5):
            for stiff in (1.0, 3.0):
                j_top = share * top_inertia
                j_pipe = (1 - share) * top_inertia
                c_1 = 0.05 * math.sqrt(stiff * k * j_pipe)
                starts.append(np.array([
                    math.log(j_top), d_start, twist_start, math.log(j_pipe),
                    math.log(stiff * k), math.log(c_1), twist_start, 0.0,
                ]))  # fmt: skip
    else:
        starts.append(np.array([math.log(top_inertia), d_start, twist_start]))
    held: dict[int, float] = {}
    held_reason: dict[str, str] = {}
    while True:
        best: tuple[float, npt.NDArray[np.float64]] | None = None
        problem = _TopSideProblem(window, lower, loop, pipe, held)
        for theta0 in starts:
            theta, cost, _ = _levenberg_marquardt(problem, theta0.copy(), 40)
            if best is None or cost < best[0]:
                best = (cost, theta)
        assert best is not None
        cost, theta = best
        r = problem.residuals(theta)
        jac = _jacobian(problem, theta)
        free = [i for i in range(theta.size) if i not in held]
        jf = jac[:, free]
        n = r.size
        fraction = _effective_fraction(r)
        s2 = cost / max(n - len(free), 1)
        info = jf.T @ jf
        ridge = 1e-10 * max(float(np.trace(info)), 1e-300) / info.shape[0]
        cov = np.linalg.inv(info + ridge * np.eye(len(free))) * s2 / fraction
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        rel = {STRING_NAMES[i]: float(std[m]) for m, i in enumerate(free) if i < 6 and i != 2}
        dampings = [n for n in ("damping_nm_s_rad", "pipe_damping_nm_s_rad") if n in rel]
        worst = max(dampings, key=lambda name: rel[name], default="")
        if not worst or rel[worst] <= MAX_RELATIVE_STD:
            break
        index = STRING_NAMES.index(worst)
        held[index] = math.log(1e-9)
        held_reason[worst] = (
            f"not identifiable from this window (relative std {rel[worst]:.2g}): held at 0"
        )
        starts = [theta]
    x, _ = problem.unpack(theta)
    values = {"top_inertia_kg_m2": float(x[0]), "damping_nm_s_rad": float(x[1])}
    if pipe:
        values.update(
            pipe_inertia_kg_m2=float(x[4]), pipe_stiffness_nm_rad=float(x[5]),
            pipe_damping_nm_s_rad=float(x[6]),
        )  # fmt: skip
    for name in held_reason:
        values[name] = 0.0
    n_eff = max(n * fraction, len(free) + 2.0)
    fit = StringModelFit(
        "pipe" if pipe else "one_inertia", values, rel, held_reason,
        math.sqrt(cost / n), n_eff * math.log(cost / n) + len(free) * math.log(n_eff), len(free),
    )  # fmt: skip
    return fit, r


def identify_string(
    window: MeasuredLog,
    lower: tuple[float, float],
    loop: tuple[float, float, float],
    top_inertia: float,
) -> StringFit:
    """Whether the log supports a pipe inertia between the top drive and the bit side.

    Two models of the string above the bit side are fitted to the measured top speed and
    surface torque, each under the identified PI speed ``loop = (k_p, k_i, r)`` and hanging
    down to the measured bit speed (:func:`drill_env.bit_model.simulate_top_side`, the bit
    side's spring ``lower = (k, c)`` at the bottom): the top drive alone on that spring
    (``one_inertia``: ``J_t``, its damping to ground ``d_t``), and a pipe ``J_p`` joined to
    the top drive by ``k_1, c_1`` between them (``pipe``); ``top_inertia`` (kg m^2) sets the
    starts. The pipe is chosen when its BIC (the one-inertia residual's effective sample size
    for both) is lower and its two inertias and its stiffness are identified (Laplace
    relative std at most :data:`MAX_RELATIVE_STD`); damping terms the data cannot identify
    are held at 0 and reported.
    """
    needed = ("surface_torque_nm", "bit_speed_rad_s", "top_speed_rad_s")
    if not all(window.has(name) for name in needed):
        return StringFit({}, "one_inertia", "the window lacks the surface torque or bit speed")
    one, r_one = _fit_string_model(window, lower, loop, False, top_inertia)
    pipe, r_pipe = _fit_string_model(window, lower, loop, True, top_inertia)
    n = r_one.size
    n_eff = max(n * _effective_fraction(r_one), pipe.free + 2.0)
    for model, r in ((one, r_one), (pipe, r_pipe)):
        model.bic = n_eff * math.log(float(r @ r) / n) + model.free * math.log(n_eff)
    identified = all(
        pipe.relative_std.get(name, math.inf) <= MAX_RELATIVE_STD
        for name in ("top_inertia_kg_m2", "pipe_inertia_kg_m2", "pipe_stiffness_nm_rad")
    )
    models = {"one_inertia": one, "pipe": pipe}
    bridged = driving_bit_speed(window)[1]
    if pipe.bic < one.bic and identified:
        return StringFit(models, "pipe", bridged_spikes=bridged)
    why = (
        "the one-inertia model has the lower BIC"
        if pipe.bic >= one.bic
        else "the pipe's or the top drive's inertia or the pipe's stiffness is not "
        "identifiable from the window"
    )
    return StringFit(models, "one_inertia", why, bridged)


def top_drive_vector(plant: CalibratedPlant) -> npt.NDArray[np.float64]:
    """The plant's identified top drive as ``(J_t, k_p, k_i, r)``; ValueError without one."""
    top = plant.top_drive or {}
    missing = [key for key in TOP_DRIVE_KEYS if key not in top]
    if missing:
        raise ValueError(
            "the plant has no identified top drive (top_drive lacks "
            f"{', '.join(missing)}): calibrate it on a log with a surface_torque_nm column "
            "to run it free"
        )
    return np.array([float(top[key]) for key in TOP_DRIVE_KEYS])


def simulate_free(
    plant: CalibratedPlant, log: MeasuredLog
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
]:
    """Run ``plant`` free on the log's clock: its identified top drive under its speed loop
    instead of the measured top speed (:func:`drill_env.bit_model.simulate_free_running`).

    The initial state is estimated from the log's first samples: the measured top and bit
    speeds, the loop's integrator from the measured surface torque (or the steady one, from
    the mean torque on bit, without it), and the twist that best matches the first
    :data:`INITIAL_STATE_FRACTION` of the log (a grid of 61 values as in
    :func:`initial_twist`); the parameters are not touched.

    Returns:
        ``(top_speed_rad_s, bit_speed_rad_s, bit_torque_nm, surface_torque_nm)``.
    """
    top_drive = top_drive_vector(plant)
    j_t, kp, ki, reference = top_drive
    string = np.array([float((plant.top_drive or {}).get(key, 0.0)) for key in STRING_KEYS])
    p = plant.model_vector()
    if plant.uses_wob and not log.has("wob_n"):
        raise ValueError("the plant's friction scales with WOB but the log has no column 'wob_n'")
    wob = wob_input(log) if plant.uses_wob else None
    top0 = float(np.median(log.column("top_speed_rad_s")[:5]))
    speed0 = 0.0
    if log.has("bit_speed_rad_s"):
        bit = log.column("bit_speed_rad_s")
        speed0 = _speed0(bit, stuck_threshold(bit))
    if log.has("surface_torque_nm"):
        u0 = float(np.median(log.column("surface_torque_nm")[:5]))
    elif log.has("bit_torque_nm"):
        u0 = float(np.mean(log.column("bit_torque_nm")))
    else:
        u0 = float(plant.operating_point.get("mean_bit_torque_nm", 0.0))
    integral0 = (u0 - kp * (reference - top0)) / ki
    if log.has("bit_torque_nm"):
        torque0 = float(np.median(log.column("bit_torque_nm")[:5]))
        balance = (torque0 - p[P_C] * (top0 - speed0)) / p[P_K]
    else:
        balance = plant.initial_twist_rad
    twist0 = balance
    if log.has("bit_speed_rad_s") and log.has("bit_torque_nm"):
        n = max(3, int(INITIAL_STATE_FRACTION * log.time_s.size))
        head = log.time_s[:n]
        bit = log.column("bit_speed_rad_s")[:n]
        torque = log.column("bit_torque_nm")[:n]
        scale = float(np.mean(wob[:n])) if wob is not None else 1.0
        span = p[P_AA] * scale / p[P_K]
        scales = (float(np.std(bit)) or 1.0, float(np.std(torque)) or 1.0)
        best = (math.inf, balance)
        for x0 in balance + span * np.linspace(-1.0, 1.0, 61):
            _, s, q, _ = simulate_free_running(
                head, p, plant.family, top_drive, float(x0), top0, speed0, integral0,
                None if wob is None else wob[:n], string=string,
            )  # fmt: skip
            cost = float(np.mean(((s - bit) / scales[0]) ** 2 + ((q - torque) / scales[1]) ** 2))
            if cost < best[0]:
                best = (cost, float(x0))
        twist0 = best[1]
    return simulate_free_running(
        log.time_s,
        p,
        plant.family,
        top_drive,
        twist0,
        top0,
        speed0,
        integral0,
        wob,
        string=string,
    )
