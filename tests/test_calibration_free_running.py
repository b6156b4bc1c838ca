"""The free-running mode: the top drive identified from the log's top speed and surface
torque, and the calibrated plant run under its own speed loop, against the lab rig's
independent closed-loop integration."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drill_env.bit_model import simulate_free_running
from drill_env.calibrated_plant import CalibratedPlant, FittedParameter, parameter_unit
from drill_env.measured_log import MeasuredLog
from experiments.calibration_fit import (
    features,
    identify_top_drive,
    simulate_free,
    stuck_threshold,
)
from experiments.synthetic_log import LAB_TRUTH, LabRig, _lab_run, lab_log

TRUTH = np.array(
    [LAB_TRUTH.J_bit, LAB_TRUTH.k, LAB_TRUTH.c, LAB_TRUTH.a_static, LAB_TRUTH.a_sliding,
     LAB_TRUTH.xi, LAB_TRUTH.c_v, LAB_TRUTH.tau]
)  # fmt: skip


def _rig_values(rig: LabRig) -> tuple[float, ...]:
    return (
        rig.J_top, rig.J_bit, rig.k, rig.c, rig.a_static, rig.a_sliding, rig.xi, rig.c_v,
        rig.tau, rig.kp, rig.ki, rig.reference_rad_s, rig.wob_n,
    )  # fmt: skip


def test_free_running_plant_follows_the_rig_closed_loop() -> None:
    """Started from the rig's state in the middle of a stuck phase, the free-running plant
    (the bit side and a top drive under a PI loop, both at the rig's values) tracks the rig's
    own fine-step closed-loop integration through several stick-slip cycles."""
    rig = LAB_TRUTH
    out = _lab_run(_rig_values(rig), 7.0, 1e-3, 1e-6, 0.0, -1.0, -1.0)
    t = np.arange(out.shape[0]) * 1e-3
    stuck = np.flatnonzero((out[:, 1] == 0.0) & (t > 1.5))
    start = int(stuck[10])  # inside a stuck run, after the reference's ramp
    top0, torque0, surface0 = out[start, 0], out[start, 2], out[start, 4]
    twist0 = (torque0 - rig.c * top0) / rig.k
    integral0 = (surface0 - rig.kp * (rig.reference_rad_s - top0)) / rig.ki
    top_drive = np.array([rig.J_top, rig.kp, rig.ki, rig.reference_rad_s])
    tail = slice(start, None)
    top, speed, torque, surface = simulate_free_running(
        t[tail], TRUTH, "memory", top_drive, twist0, top0, 0.0, integral0, out[tail, 3]
    )
    bit = out[tail, 1]
    assert np.mean(bit == 0.0) > 0.2  # it does stick-slip
    # The torque on bit jumps where the bit stops (from the sliding law to the string's
    # torque): a stop a sample earlier or later is a large error at that sample.
    pairs = ((speed, bit, 0.05), (torque, out[tail, 2], 0.1), (top, out[tail, 0], 0.05),
             (surface, out[tail, 4], 0.05))  # fmt: skip
    for simulated, reference, tolerance in pairs:
        error = np.sqrt(np.mean((simulated - reference) ** 2)) / np.std(reference)
        assert error < tolerance
    threshold = stuck_threshold(bit)
    rig_features = features(t[tail], bit, out[tail, 2], threshold)
    free_features = features(t[tail], speed, torque, threshold)
    assert free_features["period_cycles_s"] == pytest.approx(
        rig_features["period_cycles_s"], rel=0.005
    )


@pytest.mark.parametrize("seed", [4, 5])
def test_top_drive_is_identified_from_top_speed_and_surface_torque(seed: int) -> None:
    """Inertia from the momentum balance, the PI gains and the reference from the surface
    torque, on a noisy log of a rig whose values differ from the docs' log."""
    rig = dataclasses.replace(LAB_TRUTH, J_top=0.12, kp=0.9, ki=2.0, reference_rad_s=2.5)
    log = lab_log(seed=seed, duration_s=7.0, defects=False, rig=rig).window(2.0, 6.0)
    fit = identify_top_drive(log, rig.J_bit)
    assert fit.values is not None, fit.reason
    assert fit.values["inertia_kg_m2"] == pytest.approx(rig.J_top, rel=0.03)
    assert fit.values["speed_gain_nm_s_rad"] == pytest.approx(rig.kp, rel=0.03)
    assert fit.values["integral_gain_nm_rad"] == pytest.approx(rig.ki, rel=0.03)
    assert fit.values["reference_speed_rad_s"] == pytest.approx(rig.reference_rad_s, rel=0.01)
    assert fit.loop_r2 > 0.9


def _plant(top_drive: dict[str, float] | None) -> CalibratedPlant:
    names = ("bit_inertia", "stiffness", "damping", "static_friction", "sliding_friction",
             "stribeck_rate", "viscous_friction", "memory_time")  # fmt: skip
    return CalibratedPlant(
        family="memory",
        uses_wob=True,
        parameters={
            n: FittedParameter(float(v), parameter_unit(n, True))
            for n, v in zip(names, TRUTH, strict=True)
        },
        top_drive=top_drive,
    )


def test_a_log_without_surface_torque_says_so_and_free_running_needs_a_top_drive() -> None:
    log = lab_log(seed=1, duration_s=4.0, defects=False)
    columns = {n: log.column(n) for n in log.columns if n != "surface_torque_nm"}
    bare = MeasuredLog(log.time_s, columns)
    fit = identify_top_drive(bare, LAB_TRUTH.J_bit)
    assert fit.values is None
    assert "surface_torque_nm" in fit.reason
    with pytest.raises(ValueError, match="no identified top drive"):
        simulate_free(_plant(None), bare)


def test_free_running_replay_of_the_true_plant_matches_the_log() -> None:
    """The rig's own plant and top drive, run free from the state estimated on a noisy log's
    first samples, reproduce the log's period within 1 % and its bit speed closely: a
    measured top speed is not needed to keep the phase."""
    log = lab_log(seed=2, duration_s=10.0, defects=False).window(5.0, 9.0)
    rig = LAB_TRUTH
    top_drive = {
        "inertia_kg_m2": rig.J_top,
        "speed_gain_nm_s_rad": rig.kp,
        "integral_gain_nm_rad": rig.ki,
        "reference_speed_rad_s": rig.reference_rad_s,
    }
    _, speed, torque, _ = simulate_free(_plant(top_drive), log)
    bit = log.column("bit_speed_rad_s")
    threshold = stuck_threshold(bit)
    measured = features(log.time_s, bit, log.column("bit_torque_nm"), threshold)
    simulated = features(log.time_s, speed, torque, threshold)
    assert simulated["period_cycles_s"] == pytest.approx(measured["period_cycles_s"], rel=0.01)
    assert np.sqrt(np.mean((speed - bit) ** 2)) / np.std(bit) < 0.2
