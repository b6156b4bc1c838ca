"""The uncertainty of the calibration: the jackknife over whole stick-slip cycles sees the
measurement noise, and its intervals cover the known parameters of synthetic logs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drill_env.bit_model import simulate_bit
from drill_env.measured_log import MeasuredLog
from experiments.calibration_fit import (
    JACKKNIFE_MAX_GROUPS,
    WEAKLY_PINNED,
    Bootstrap,
    FamilyFit,
    _plant_of,
    calibrate,
    cycle_labels,
    stuck_segments,
    student_t_975,
    wob_input,
)
from experiments.synthetic_log import LAB_TRUTH, _lab_run

TRUTH = {
    "bit_inertia": LAB_TRUTH.J_bit,
    "stiffness": LAB_TRUTH.k,
    "damping": LAB_TRUTH.c,
    "static_friction": LAB_TRUTH.a_static,
    "sliding_friction": LAB_TRUTH.a_sliding,
    "stribeck_rate": LAB_TRUTH.xi,
}
"""The parameters of the logs of :func:`_log` (karnopp family)."""


def _log(noise_scale: float, seed: int = 1) -> MeasuredLog:
    """A log of the fit's own Karnopp model (known parameters) driven by the lab rig's top
    speed, with the lab log's noise times ``noise_scale`` on the bit speed and torque."""
    rig = dataclasses.replace(LAB_TRUTH, c_v=0.0, tau=1e-4)
    values = (
        rig.J_top, rig.J_bit, rig.k, rig.c, rig.a_static, rig.a_sliding, rig.xi, rig.c_v,
        rig.tau, rig.kp, rig.ki, rig.reference_rad_s, rig.wob_n,
    )  # fmt: skip
    out = _lab_run(values, 5.0, 1e-3, 1e-5, 0.05, -1.0, -1.0)
    t = np.arange(out.shape[0]) * 1e-3
    rng = np.random.default_rng(seed)
    top = out[:, 0] + rng.normal(0.0, 0.03, t.size)
    wob = out[:, 3] + rng.normal(0.0, 2.0, t.size)
    truth = np.array([rig.J_bit, rig.k, rig.c, rig.a_static, rig.a_sliding, rig.xi, 0.0, 0.0])
    wob_in = wob_input(MeasuredLog(t, {"top_speed_rad_s": top, "wob_n": wob}))
    speed, torque, _ = simulate_bit(t, top, truth, "karnopp", 0.0, 0.0, wob_in)
    return MeasuredLog(
        t,
        {
            "top_speed_rad_s": top,
            "wob_n": wob,
            "bit_speed_rad_s": speed + noise_scale * rng.normal(0.0, 0.05, t.size),
            "bit_torque_nm": torque + noise_scale * rng.normal(0.0, 0.03, t.size),
        },
    )


def test_the_spread_grows_with_the_measurement_noise() -> None:
    """Four times the noise: the inertia's and the stiffness's jackknife spread grows (at
    least 1.5 times: it also holds where the optimiser stops on a rough cost, which does not
    scale with the noise; a Laplace spread would grow four times), and every identified
    parameter has an interval."""
    quiet = calibrate(_log(1.0), (2.0, 5.0), families=("karnopp",)).plant
    noisy = calibrate(_log(4.0), (2.0, 5.0), families=("karnopp",)).plant
    for name in ("bit_inertia", "stiffness"):
        low, high = quiet.parameters[name].relative_std, noisy.parameters[name].relative_std
        assert low is not None and high is not None
        assert high > 1.5 * low, name
    for plant in (quiet, noisy):
        for p in plant.parameters.values():
            if p.identified:
                assert p.interval_95 is not None and p.interval_95[0] <= p.interval_95[1]
                assert p.relative_std is not None and p.relative_std > 0


def test_student_t_quantile() -> None:
    stats = pytest.importorskip("scipy.stats")
    for dof in (1, 2, 4, 5, 19, 20, 21, 30, 100, 1000):
        assert student_t_975(dof) == pytest.approx(stats.t.ppf(0.975, dof), abs=1e-3)
    with pytest.raises(ValueError, match="dof"):
        student_t_975(0)


def test_jackknife_groups_are_whole_cycles() -> None:
    """Groups start in the middle of measured stuck runs, follow each other in time, and
    are at most JACKKNIFE_MAX_GROUPS."""
    log = _log(1.0).window(0.5, 5.0)
    labels = cycle_labels(log)
    assert labels is not None
    runs = stuck_segments(log, 1)
    assert runs is not None and len(runs) >= 5
    assert np.all(np.diff(labels) >= 0) and np.all(np.diff(labels) <= 1)
    groups = int(labels.max()) + 1
    assert groups == min(len(runs), JACKKNIFE_MAX_GROUPS)
    starts = {int(a) for a, *_ in runs}
    assert all(int(i) + 1 in starts for i in np.flatnonzero(np.diff(labels)))
    assert cycle_labels(log.window(0.5, 1.2)) is None  # too few cycles: no jackknife


def _coverage(seeds: tuple[int, ...]) -> tuple[int, int]:
    """How many of the known parameters fall inside their 95 % intervals, of how many."""
    inside = total = 0
    for seed in seeds:
        plant = calibrate(_log(1.0, seed), (2.0, 5.0), families=("karnopp",)).plant
        for name, truth in TRUTH.items():
            p = plant.parameters[name]
            if p.interval_95 is None:
                continue
            total += 1
            inside += p.interval_95[0] <= truth <= p.interval_95[1]
    print(f"coverage of the 95 % intervals on seeds {seeds}: {inside}/{total}")
    return inside, total


def test_intervals_cover_the_known_parameters() -> None:
    """A log of the fit's own model with known parameters: at least two thirds of them inside
    their intervals (the slow test runs more seeds)."""
    inside, total = _coverage((2,))
    assert total >= 5
    assert inside >= 2 * total / 3


@pytest.mark.slow
def test_intervals_cover_the_known_parameters_over_seeds() -> None:
    """Four seeds: at least three quarters of the known parameters inside their intervals
    (the nominal 95 % is not reached: docs/calibration.md section 5 says why)."""
    inside, total = _coverage((1, 3, 4, 5))
    assert inside >= 0.75 * total


def test_a_parameter_the_cycles_do_not_agree_on_is_reported_as_weakly_pinned() -> None:
    """A jackknife spread above the identifiability limit is stated in the parameter's note
    (the value alone would read as if the data pinned it)."""
    log = _log(1.0)
    names = list(TRUTH)
    p = np.array([TRUTH[n] for n in names] + [0.0, 0.0])
    fit = FamilyFit("karnopp", p, 0.0, 1.0, 10, 5.0, names, {}, {}, {}, 0.0, 0)
    spread = {n: (0.8 if n == "stribeck_rate" else 0.01) for n in names}
    boot = Bootstrap(spread, {n: (0.5 * TRUTH[n], 2 * TRUTH[n]) for n in names}, 5, 0,
                     "cycle_jackknife")  # fmt: skip
    weights = np.ones(2 * log.time_s.size)
    plant = _plant_of(fit, log, True, (0.0, 5.0), "", {"karnopp": fit}, [], weights, boot)
    for name in names:
        assert (WEAKLY_PINNED in plant.parameters[name].note) == (name == "stribeck_rate")
        assert plant.parameters[name].relative_std == spread[name]
