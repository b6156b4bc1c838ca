"""baselines.autodriller: the min-select driller's loop, alone and as the axial loop of
``DrillStringCoupled-v0``."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from baselines.autodriller import Autodriller, AutodrillerGains
from drill_env.coupled_env import (
    AxialMeasurement,
    AxialSetup,
    DrillStringCoupledEnv,
    axial_controller_names,
    make_axial_controller,
)

SETUP = AxialSetup("force", 90e3, 0.01, 0.0, 250e3, 50e3)


def _measure(wob: float, command: float, rop: float = 0.01, torque: float = 10e3):
    return AxialMeasurement(wob, rop, torque, torque, command)


def test_registered_once() -> None:
    assert "autodriller" in axial_controller_names()
    assert baselines.AXIAL_BUILT_IN["autodriller"] is Autodriller
    assert isinstance(make_axial_controller("autodriller", kp=0.1), Autodriller)


def test_pi_in_velocity_form() -> None:
    """Constant relative error ``e``: the first step adds ``S ki e dt`` (no proportional kick
    from the first sample), a step of the error adds ``S kp (e1 - e0)`` more."""
    a = Autodriller(kp=0.5, ki=2.0)
    a.reset(SETUP)
    u = a.command(_measure(81e3, 90e3), 0.05)  # e = 0.1
    assert u == pytest.approx(90e3 + 90e3 * 2.0 * 0.1 * 0.05)
    u2 = a.command(_measure(72e3, u), 0.05)  # e = 0.2
    assert u2 == pytest.approx(u + 90e3 * (0.5 * 0.1 + 2.0 * 0.2 * 0.05))
    assert a.active == "wob"


def test_min_select_torque_limit_wins_and_clips() -> None:
    a = Autodriller(torque_limit_nm=8e3)
    a.reset(SETUP)
    u = a.command(_measure(80e3, 90e3, torque=12e3), 0.05)
    assert a.active == "torque" and u < 90e3
    b = Autodriller()
    b.reset(SETUP._replace(max_command=91e3))
    assert b.command(_measure(0.0, 90.9e3), 1.0) == 91e3  # clipped to the env's range


def test_bad_gains() -> None:
    with pytest.raises(ValueError, match=r"AutodrillerGains.kp = -1.0 is out of range"):
        AutodrillerGains(kp=-1.0)
    with pytest.raises(TypeError, match="unrecognized gain"):
        Autodriller(kd=1.0)
    with pytest.raises(RuntimeError, match="reset"):
        Autodriller().command(_measure(1.0, 1.0), 0.1)


def test_holds_the_weight_on_bit_on_a_harder_rock_where_a_fixed_hook_speed_piles_it_up() -> None:
    """Hook-speed input; the reset seed 10 draws a rock 18 % harder than the nominal one. The
    fixed hook speed (the steady ROP on the nominal rock) is too fast for it, so the string
    piles weight on the bit; the autodriller brings the mean WOB of the last 10 s back to its
    set point."""
    wobs = {}
    for loop in ("fixed", "autodriller"):
        env = DrillStringCoupledEnv(
            axial_input="hook_speed", force_loop=loop, reference_speed_rad_s=20.0,
            applied_force_n=60e3, episode_s=40.0,
        )  # fmt: skip
        env.reset(seed=10)
        tail = []
        for k in range(800):
            _, _, terminated, _, info = env.step(np.zeros(2, dtype=np.float32))
            assert not terminated
            if k >= 600:
                tail.append(info["wob_n"])
        wobs[loop] = float(np.mean(tail))
    assert wobs["fixed"] > 65e3
    assert wobs["autodriller"] == pytest.approx(60e3, rel=0.02)
