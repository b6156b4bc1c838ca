"""Synthetic measured logs with known parameters, noise and defects (docs/calibration.md
section 4): a laboratory rig and a field well, written in the log format of
:mod:`drill_env.measured_log`.

* :func:`lab_log`: a laboratory rig (a few N m, up to ~150 rpm, 1 kHz): a motor with a PI speed
  loop drives a slender shaft and a bit whose friction has memory (hysteretic torque-speed
  loops), integrated here with its own fine-step scheme (5e5 steps per second), independent of
  the calibration's simulator.
* :func:`field_log`: a field well from the project's 4-DOF plant (``zribi2024``, integrated by
  :func:`drill_env.integration.plant_step`) under a PI speed loop of the top drive, sampled
  like downhole telemetry (5 Hz).

Both add white measurement noise from a seeded generator and, with ``defects``, a gap, spikes,
a flat line of a sensor and a stall of the top drive at stated times.

``python -m experiments.synthetic_log OUT [--seed N]`` writes both as ``OUT/lab_log.csv`` and
``OUT/field_log.csv`` (existing files of these names are refused).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.friction import STUCK
from drill_env.integration import plant_step
from drill_env.measured_log import MeasuredLog, write_log_csv
from drill_env.parameters import PRESETS, plant_parameter_vector
from experiments.arguments import ArgumentParser, run_command, seed_option

__all__ = ["LAB_TRUTH", "LabRig", "field_log", "lab_log", "main"]


@dataclass(frozen=True)
class LabRig:
    """A laboratory rig: motor, shaft, bit and a friction with memory.

    Attributes:
        J_top: Motor and table inertia, kg m^2.
        J_bit: Bit inertia, kg m^2.
        k: Shaft stiffness, N m/rad.
        c: Shaft damping, N m s/rad.
        a_static: Static friction per newton of WOB (mu_a R), m.
        a_sliding: Sliding friction per newton of WOB (mu_0 R), m.
        xi: Stribeck decline rate, s/rad.
        c_v: Viscous bit friction, N m s/rad.
        tau: Friction memory time, s.
        kp: Motor speed loop proportional gain, N m s/rad.
        ki: Motor speed loop integral gain, N m/rad.
        reference_rad_s: Motor speed reference, rad/s.
        wob_n: Mean weight on bit, N.
    """

    J_top: float = 0.08
    J_bit: float = 0.02
    k: float = 1.5
    c: float = 0.01
    a_static: float = 0.0125
    a_sliding: float = 0.0075
    xi: float = 0.5
    c_v: float = 0.01
    tau: float = 0.05
    kp: float = 0.6
    ki: float = 1.5
    reference_rad_s: float = 3.0
    wob_n: float = 200.0


LAB_TRUTH: Final = LabRig()
"""The rig of the synthetic laboratory log."""
LAB_NOISE: Final = {
    "top_speed_rad_s": 0.03,
    "bit_speed_rad_s": 0.05,
    "bit_torque_nm": 0.03,
    "wob_n": 2.0,
    "surface_torque_nm": 0.03,
}
"""Standard deviation of the white measurement noise of each column of the lab log."""
LAB_DEFECTS: Final[dict[str, tuple[float, ...]]] = {
    "gap_s": (21.0, 21.05),
    "spikes_s": (17.3, 24.1, 35.55),
    "flat_line_s": (33.0, 33.12),
    "stall_s": (55.0, 57.0),
}
"""Where the lab log's defects are, s (the calibration and replay windows avoid them)."""


@njit(cache=True)
def _lab_run(rig, duration_s, out_dt, h, wob_wave, stall_start, stall_end):  # fmt: skip
    (j_top, j_bit, k, c, a_a, a_0, xi, c_v, tau, kp, ki, ref, wob0) = rig
    n_out = int(round(duration_s / out_dt)) + 1
    per = int(round(out_dt / h))
    out = np.empty((n_out, 5))
    wt = 0.0
    wb = 0.0
    twist = 0.0
    integ = 0.0
    v = 0.0
    stuck = True
    t = 0.0
    for i in range(n_out):
        wob = wob0 * (1.0 + wob_wave * math.sin(2 * math.pi * 0.05 * t))
        t_a = a_a * wob
        t_0 = a_0 * wob
        t_e = k * twist + c * (wt - wb)
        if stuck:
            t_bit = t_e
        else:
            d = 1.0 if wb > 0 else -1.0
            t_bit = d * (t_0 + (t_a - t_0) * math.exp(-xi * v)) + c_v * wb
        out[i, 0] = wt
        out[i, 1] = wb
        out[i, 2] = t_bit
        out[i, 3] = wob
        r_now = ref
        if stall_start <= t < stall_end:
            r_now = 0.0
        elif t < 1.0:
            r_now = ref * t
        out[i, 4] = kp * (r_now - wt) + ki * integ
        for _ in range(per):
            r = ref
            if stall_start <= t < stall_end:
                r = 0.0
            elif t < 1.0:
                r = ref * t
            wob = wob0 * (1.0 + wob_wave * math.sin(2 * math.pi * 0.05 * t))
            t_a = a_a * wob
            t_0 = a_0 * wob
            err = r - wt
            u = kp * err + ki * integ
            integ += h * err
            t_e = k * twist + c * (wt - wb)
            if stuck:
                if abs(t_e) > t_a:
                    stuck = False
                    wb = 1e-12 if t_e > 0 else -1e-12
                    acc = 0.0
                else:
                    acc = 0.0
            if not stuck:
                d = 1.0 if wb > 0 else -1.0
                t_bit = d * (t_0 + (t_a - t_0) * math.exp(-xi * v)) + c_v * wb
                acc = (t_e - t_bit) / j_bit
            wt_new = wt + h * (u - t_e) / j_top
            wb_new = wb + h * acc
            if not stuck and wb_new * wb <= 0.0:
                if abs(k * twist + c * wt) <= t_a:
                    stuck = True
                wb_new = 0.0 if stuck else -wb
            twist += h * (wt - wb)
            v += (abs(wb) - v) * h / tau
            wt = wt_new
            wb = wb_new
            t += h
    return out


def _add_defects(
    time_s: npt.NDArray[np.float64],
    columns: dict[str, npt.NDArray[np.float64]],
    gap_s: tuple[float, ...],
    spikes_s: tuple[float, ...],
    flat_line_s: tuple[float, ...],
    spike_column: str,
    flat_column: str,
) -> tuple[npt.NDArray[np.float64], dict[str, npt.NDArray[np.float64]]]:
    for s in spikes_s:
        i = int(np.searchsorted(time_s, s))
        if i >= time_s.size - 1:
            continue  # the log ends before it
        values = columns[spike_column]
        values[i] += 8.0 * float(np.std(values)) * (1 if i % 2 else -1)
    a, b = np.searchsorted(time_s, flat_line_s)
    if a < time_s.size:
        columns[flat_column][a:b] = columns[flat_column][a]
    keep = (time_s <= gap_s[0]) | (time_s >= gap_s[1])
    return time_s[keep], {k: v[keep] for k, v in columns.items()}


def lab_log(
    seed: int = 0, duration_s: float = 60.0, defects: bool = True, rig: LabRig = LAB_TRUTH
) -> MeasuredLog:
    """A synthetic laboratory stick-slip log at 1 kHz, noise from ``seed``
    (:data:`LAB_NOISE`), and with ``defects`` those of :data:`LAB_DEFECTS`."""
    stall = LAB_DEFECTS["stall_s"] if defects else (-1.0, -1.0)
    values = (
        rig.J_top, rig.J_bit, rig.k, rig.c, rig.a_static, rig.a_sliding, rig.xi, rig.c_v,
        rig.tau, rig.kp, rig.ki, rig.reference_rad_s, rig.wob_n,
    )  # fmt: skip
    out = _lab_run(values, duration_s, 1e-3, 2e-6, 0.05, stall[0], stall[1])
    time_s = np.round(np.arange(out.shape[0]) * 1e-3, 9)
    rng = np.random.default_rng(seed)
    names = ("top_speed_rad_s", "bit_speed_rad_s", "bit_torque_nm", "wob_n", "surface_torque_nm")
    columns = {
        name: out[:, j] + rng.normal(0.0, LAB_NOISE[name], out.shape[0])
        for j, name in enumerate(names)
    }
    if defects:
        time_s, columns = _add_defects(
            time_s, columns, LAB_DEFECTS["gap_s"], LAB_DEFECTS["spikes_s"],
            LAB_DEFECTS["flat_line_s"], "bit_speed_rad_s", "bit_torque_nm",
        )  # fmt: skip
    return MeasuredLog(time_s, columns, "synthetic laboratory log")


FIELD_NOISE: Final = {
    "top_speed_rad_s": 0.05,
    "bit_speed_rad_s": 0.1,
    "bit_torque_nm": 200.0,
    "wob_n": 500.0,
    "surface_torque_nm": 200.0,
}
"""Standard deviation of the white measurement noise of each column of the field log."""
FIELD_DEFECTS: Final[dict[str, tuple[float, ...]]] = {
    "gap_s": (250.0, 256.0),
    "spikes_s": (130.3, 211.7),
    "flat_line_s": (300.0, 320.0),
}
"""Where the field log's defects are, s."""


@njit(cache=True)
def _field_run(p, t_a, t_0, c_bit, duration_s, out_dt, h, kp, ki, ref):  # fmt: skip
    n_out = int(round(duration_s / out_dt)) + 1
    per = int(round(out_dt / h))
    out = np.empty((n_out, 4))
    x = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    mode = STUCK
    integ = 0.0
    t = 0.0
    for i in range(n_out):
        if mode == STUCK:
            t_bit = p[7] * (x[4] - x[6]) + p[11] * x[5]
            if t_bit > t_a:
                t_bit = t_a
            elif t_bit < -t_a:
                t_bit = -t_a
        else:
            t_bit = mode * (t_0 + (t_a - t_0) * math.exp(-p[15] * abs(x[6]))) + c_bit * x[6]
        out[i, 0] = x[0]
        out[i, 1] = x[6]
        out[i, 2] = t_bit
        r_now = ref if t >= 5.0 else ref * t / 5.0
        out[i, 3] = max(kp * (r_now - x[0]) + ki * integ, 0.0)
        for _ in range(per):
            r = ref if t >= 5.0 else ref * t / 5.0
            err = r - x[0]
            u = kp * err + ki * integ
            if u < 0.0:
                u = 0.0
            else:
                integ += h * err
            x, mode = plant_step(x, mode, u, p, t_a, t_0, h)
            t += h
    return out


def field_log(
    seed: int = 0, duration_s: float = 400.0, sample_period_s: float = 0.2, defects: bool = True
) -> MeasuredLog:
    """A synthetic field log of the ``zribi2024`` 4-DOF plant at WOB 97,347 N under a stiff PI
    speed loop (reference 3 rad/s), sampled every ``sample_period_s`` with the noise of
    :data:`FIELD_NOISE` and the defects of :data:`FIELD_DEFECTS`."""
    params = PRESETS["zribi2024"]
    wob = 97_347.0
    p = plant_parameter_vector(params)
    out = _field_run(
        p, params.static_torque_nm(wob), params.sliding_torque_nm(wob), params.c_bit,
        duration_s, sample_period_s, 1e-3, 3000.0, 300.0, 3.0,
    )  # fmt: skip
    time_s = np.round(np.arange(out.shape[0]) * sample_period_s, 9)
    rng = np.random.default_rng(seed)
    names = ("top_speed_rad_s", "bit_speed_rad_s", "bit_torque_nm", "surface_torque_nm")
    columns = {
        name: out[:, j] + rng.normal(0.0, FIELD_NOISE[name], out.shape[0])
        for j, name in enumerate(names)
    }
    columns["wob_n"] = wob + rng.normal(0.0, FIELD_NOISE["wob_n"], out.shape[0])
    if defects:
        time_s, columns = _add_defects(
            time_s, columns, FIELD_DEFECTS["gap_s"], FIELD_DEFECTS["spikes_s"],
            FIELD_DEFECTS["flat_line_s"], "bit_speed_rad_s", "bit_torque_nm",
        )  # fmt: skip
    return MeasuredLog(time_s, columns, "synthetic field log (zribi2024)")


def main(argv: Sequence[str] | None = None) -> int:
    """Write ``OUT/lab_log.csv`` and ``OUT/field_log.csv``; refuses to replace existing ones."""
    parser = ArgumentParser(
        prog="python -m experiments.synthetic_log",
        description="Write the synthetic laboratory and field logs of docs/calibration.md.",
    )
    parser.add_argument("out", type=Path, help="output directory (made if missing)")
    seed_option(parser, "seed of the measurement noise")
    args = parser.parse_args(argv)

    def run() -> int:
        out: Path = args.out
        if out.exists() and not out.is_dir():
            raise ValueError(f"{str(out)!r} exists and is not a directory")
        targets: dict[str, Callable[[int], MeasuredLog]] = {
            "lab_log.csv": lab_log,
            "field_log.csv": field_log,
        }
        for name in targets:
            if (out / name).exists() or (out / name).is_symlink():
                raise ValueError(f"{str(out / name)!r} exists: not overwritten")
        out.mkdir(parents=True, exist_ok=True)
        for name, make in targets.items():
            write_log_csv(make(args.seed), out / name)
            print(f"wrote {out / name}")
        return 0

    return run_command(parser.prog, run, debug=False)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
