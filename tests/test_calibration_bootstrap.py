"""The residual block bootstrap of the calibration: it sees the measurement noise."""

from __future__ import annotations

import dataclasses

import numpy as np

from drill_env.bit_model import simulate_bit
from drill_env.measured_log import MeasuredLog
from experiments.calibration_fit import calibrate, wob_input
from experiments.synthetic_log import LAB_TRUTH, _lab_run


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


def test_bootstrap_spread_grows_with_the_measurement_noise() -> None:
    """Four times the noise: the inertia's and the stiffness's bootstrap spread grows (at
    least twice; a Laplace-like spread would grow four times), and every identified
    parameter has an interval."""
    quiet = calibrate(_log(1.0), (2.0, 5.0), families=("karnopp",)).plant
    noisy = calibrate(_log(4.0), (2.0, 5.0), families=("karnopp",)).plant
    for name in ("bit_inertia", "stiffness"):
        low, high = quiet.parameters[name].relative_std, noisy.parameters[name].relative_std
        assert low is not None and high is not None
        assert high > 2 * low, name
    for plant in (quiet, noisy):
        for p in plant.parameters.values():
            if p.identified:
                assert p.interval_95 is not None and p.interval_95[0] <= p.interval_95[1]
                assert p.relative_std is not None and p.relative_std > 0
