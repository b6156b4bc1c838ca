"""The four sliding-mode laws of docs/specification.md section 3 on hand-computed cases, their gains validation,
the registry, and the equivalence of in-loop and policy execution."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from baselines import (
    ASMCGains,
    ControllerPolicy,
    CSMCGains,
    MSMCGains,
    ProposedGains,
    SurfaceGains,
    make_controller,
)
from baselines.smc import (
    N_SMC_PARAMS,
    N_SMC_STATE,
    S_GAIN,
    S_I1,
    S_I2,
    S_SLIDING,
    VARIANT_ASMC,
    VARIANT_CSMC,
    VARIANT_MSMC,
    VARIANT_PROPOSED,
    smc_torque,
)
from drill_env.evaluation import ZeroAction, rollout

PAPER = ("csmc", "msmc", "asmc", "proposed")
LAWS = {
    "csmc": VARIANT_CSMC,
    "msmc": VARIANT_MSMC,
    "asmc": VARIANT_ASMC,
    "proposed": VARIANT_PROPOSED,
}

# zribi2024 values used by u_eq.
J_DT, C_DT, C_PI, K_PI = 930.0, 425.0, 193.61, 698.06


def law_params(name: str, lam: float = 1.0, delta: float = 0.5) -> np.ndarray:
    """Parameter vector [J_dt, c_dt, c_pi, k_pi, lam, delta, g0..] with the Table 1 gains."""
    gains = {
        "csmc": (3.0,),
        "msmc": (3.0, 0.001),
        "asmc": (0.1, 0.01),
        "proposed": (3.0, 0.001, 0.1, 0.01, 0.125),
    }[name]
    lp = np.zeros(N_SMC_PARAMS)
    values = (J_DT, C_DT, C_PI, K_PI, lam, delta, *gains)
    lp[: len(values)] = values
    return lp


def law_state(i1: float = 0.0, i2: float = 0.0, gain: float = 0.0) -> np.ndarray:
    ls = np.zeros(N_SMC_STATE)
    ls[S_I1], ls[S_I2], ls[S_GAIN] = i1, i2, gain
    return ls


# A measured state (x1..x7) with x1 = 10, x2 = 3, x3 = 9, x7 = 8 and a reference of 12 rad/s:
# u_eq = c_pi (10 - 9) + k_pi 3 + c_dt 10 - J_dt (10 - 12) - J_dt (10 - 8)
STATE = (10.0, 3.0, 9.0, 0.5, 8.5, 0.2, 8.0)
REF = 12.0
U_EQ = C_PI * 1.0 + K_PI * 3.0 + C_DT * 10.0 + J_DT * 2.0 - J_DT * 2.0  # 6537.79 N m


def u_disc(name: str, s: float, gain: float) -> float:
    """The discontinuous part of each law (docs/specification.md section 3, Table 1 gains)."""
    sgn = math.copysign(1.0, s) if s != 0 else 0.0
    if name == "csmc":
        return -3.0 * sgn
    if name == "msmc":
        return -3.0 * math.sqrt(abs(s)) * sgn - 0.001 * s
    if name == "asmc":
        return -gain * sgn
    return -gain * math.sqrt(abs(s)) * sgn - 0.01 * gain * s


class TestHandComputed:
    def test_u_eq_value(self) -> None:
        assert pytest.approx(6537.79, abs=1e-9) == U_EQ

    @pytest.mark.parametrize("name", PAPER)
    @pytest.mark.parametrize(
        ("i1", "i2", "s"),
        [(0.0, 0.0, -2.0), (0.5, 2.5, 1.0), (1.0, 3.5, 2.5), (0.0, 1.75, -0.25)],
        ids=["s=-2", "s=+1", "s=+2.5", "s=-0.25"],
    )
    def test_torque_is_u_eq_plus_u_disc(self, name: str, i1: float, i2: float, s: float) -> None:
        # s = (x1 - xd) + lam I1 + lam I2 = -2 + I1 + I2
        gain = 0.2 if name in ("asmc", "proposed") else 0.0
        ls = law_state(i1, i2, gain)
        u = smc_torque(LAWS[name], law_params(name), ls, STATE, REF, 0.01)
        assert ls[S_SLIDING] == pytest.approx(s, abs=1e-12)
        assert u == pytest.approx(U_EQ + u_disc(name, s, gain), abs=1e-9)

    @pytest.mark.parametrize("name", PAPER)
    def test_u_disc_opposes_s(self, name: str) -> None:
        for i1, sign in ((3.0, -1.0), (-3.0, 1.0)):  # s = -2 + I1 = +1 or -5
            ls = law_state(i1, 0.0, 0.2)
            u = smc_torque(LAWS[name], law_params(name), ls, STATE, REF, 0.01)
            assert np.sign(u - U_EQ) == sign

    @pytest.mark.parametrize("name", PAPER)
    def test_start_from_rest(self, name: str) -> None:
        # At rest with zero integrals: s(0) = -V_ref, u_eq = J_dt lam V_ref = 11,160 N m.
        controller = make_controller(name)
        u = controller.torque(np.zeros(7), 12.0, 1e-3)
        assert controller.sliding_variable == -12.0
        gain = controller.adaptive_gain if name in ("asmc", "proposed") else 0.0
        expected = {
            "csmc": 3.0,
            "msmc": 3.0 * math.sqrt(12.0) + 0.001 * 12.0,
            "asmc": 0.2,
            "proposed": 0.2 * math.sqrt(12.0) + 0.01 * 0.2 * 12.0,
        }[name]
        assert u == pytest.approx(J_DT * 12.0 + expected, abs=1e-9)
        if name in ("asmc", "proposed"):
            assert gain > 0.2  # |s| = 12 > delta: the gain grew during the first step

    @pytest.mark.parametrize("name", PAPER)
    def test_integrals_forward_euler(self, name: str) -> None:
        ls = law_state(0.5, 2.5, 0.2)
        smc_torque(LAWS[name], law_params(name), ls, STATE, REF, 0.01)
        # I1 += (x1 - xd) dt = -2 * 0.01; I2 += (x1 - x7) dt = 2 * 0.01
        assert ls[S_I1] == pytest.approx(0.48, abs=1e-15)
        assert ls[S_I2] == pytest.approx(2.52, abs=1e-15)

    def test_integrals_through_the_class(self) -> None:
        c = make_controller("csmc")
        m = np.array(STATE)
        c.torque(m, REF, 0.5)  # s = -2, then I1 = -1, I2 = +1
        c.torque(m, REF, 0.5)
        assert c.sliding_variable == pytest.approx(-2.0 + (-1.0) + 1.0)


class TestAdaptiveGains:
    """ASMC: k' = mu11 |s| sign(|s| - delta) while k > mu22, else mu22.
    Proposed: k' = mu1 |s|^b sign(|s| - delta) while k > alpha, else mu2."""

    DT = 0.01

    def step_gain(self, name: str, s: float, gain: float) -> float:
        ls = law_state(s + 2.0, 0.0, gain)  # s = -2 + I1
        smc_torque(LAWS[name], law_params(name), ls, STATE, REF, self.DT)
        assert ls[S_SLIDING] == pytest.approx(s, abs=1e-12)
        return float(ls[S_GAIN])

    @pytest.mark.parametrize("s", [1.0, -3.0])
    def test_asmc_grows_outside_delta(self, s: float) -> None:
        assert self.step_gain("asmc", s, 0.2) == pytest.approx(0.2 + 0.1 * abs(s) * self.DT)

    @pytest.mark.parametrize("s", [0.25, -0.4])
    def test_asmc_shrinks_inside_delta(self, s: float) -> None:
        assert self.step_gain("asmc", s, 0.2) == pytest.approx(0.2 - 0.1 * abs(s) * self.DT)

    def test_asmc_holds_on_delta(self) -> None:
        assert self.step_gain("asmc", 0.5, 0.2) == 0.2  # sign(0) = 0

    @pytest.mark.parametrize("gain", [0.01, 0.005], ids=["at mu22", "below mu22"])
    @pytest.mark.parametrize("s", [0.25, 3.0])
    def test_asmc_floor(self, gain: float, s: float) -> None:
        # At or below mu22 the gain grows at mu22 whatever s is.
        assert self.step_gain("asmc", s, gain) == pytest.approx(gain + 0.01 * self.DT)

    @pytest.mark.parametrize("s", [1.0, -3.0])
    def test_proposed_grows_outside_delta(self, s: float) -> None:
        expected = 0.2 + 3.0 * abs(s) ** 0.125 * self.DT
        assert self.step_gain("proposed", s, 0.2) == pytest.approx(expected)

    @pytest.mark.parametrize("s", [0.25, -0.4])
    def test_proposed_shrinks_inside_delta(self, s: float) -> None:
        expected = 0.5 - 3.0 * abs(s) ** 0.125 * self.DT
        assert self.step_gain("proposed", s, 0.5) == pytest.approx(expected)

    @pytest.mark.parametrize("gain", [0.1, 0.05], ids=["at alpha", "below alpha"])
    @pytest.mark.parametrize("s", [0.25, 3.0])
    def test_proposed_floor(self, gain: float, s: float) -> None:
        assert self.step_gain("proposed", s, gain) == pytest.approx(gain + 0.001 * self.DT)

    def test_proposed_just_above_alpha_adapts(self) -> None:
        assert self.step_gain("proposed", 0.25, 0.1 + 1e-9) < 0.1

    @pytest.mark.parametrize("name", ["csmc", "msmc"])
    def test_fixed_gain_laws_have_no_gain(self, name: str) -> None:
        assert self.step_gain(name, 1.0, 0.0) == 0.0

    @pytest.mark.parametrize("name", ["asmc", "proposed"])
    def test_reset_restores_initial_gain(self, name: str) -> None:
        c = make_controller(name, k0=0.3)
        for _ in range(10):
            c.torque(np.zeros(7), 12.0, 0.1)
        assert c.adaptive_gain != 0.3
        c.reset()
        assert c.adaptive_gain == 0.3
        assert c.sliding_variable == 0.0


class TestGainsValidation:
    @pytest.mark.parametrize(
        ("make", "match"),
        [
            (lambda: CSMCGains(k1=-1.0), r"CSMCGains\.k1 = -1\.0 is out of range: allowed > 0"),
            (lambda: CSMCGains(k1=0.0), r"CSMCGains\.k1 = 0\.0 is out of range: allowed > 0"),
            (lambda: MSMCGains(k3=-0.1), r"MSMCGains\.k3 = -0\.1 is out of range: allowed >= 0"),
            (lambda: ASMCGains(mu22=0.0), r"ASMCGains\.mu22 = 0\.0 is out of range: allowed > 0"),
            (
                lambda: ProposedGains(b=1.5),
                r"ProposedGains\.b = 1\.5 is out of range: allowed \(0, 1\]",
            ),
            (
                lambda: ProposedGains(k0=0.05),
                r"ProposedGains\.k0 = 0\.05 is out of range: allowed > alpha = 0\.1",
            ),
            (lambda: SurfaceGains(lam=0.0), r"SurfaceGains\.lam = 0\.0 is out of range"),
            (lambda: CSMCGains(delta=-1.0), r"CSMCGains\.delta = -1\.0 is out of range"),
            (lambda: CSMCGains(k1=math.nan), r"CSMCGains\.k1 must be finite, got nan"),
        ],
        ids=[
            "negative",
            "zero",
            "msmc k3",
            "asmc mu22",
            "b>1",
            "k0<alpha",
            "lam",
            "delta",
            "nan",
        ],  # fmt: skip
    )
    def test_bad_gain(self, make, match: str) -> None:  # type: ignore[no-untyped-def]
        with pytest.raises(ValueError, match=match):
            make()

    def test_non_numeric_gain(self) -> None:
        with pytest.raises(TypeError, match=r"CSMCGains\.k1 must be a real number, got '3'"):
            CSMCGains(k1="3")  # type: ignore[arg-type]

    def test_override_is_validated(self) -> None:
        with pytest.raises(ValueError, match=r"ASMCGains\.mu11 = -2.0 is out of range"):
            make_controller("asmc", mu11=-2)

    def test_unknown_gain(self) -> None:
        with pytest.raises(
            TypeError, match=r"unrecognized gain\(s\) for csmc: k9; valid gains: lam, delta, k1"
        ):
            make_controller("csmc", k9=1.0)

    def test_wrong_gains_type(self) -> None:
        from baselines import CSMC

        with pytest.raises(TypeError, match="csmc needs CSMCGains, got MSMCGains"):
            CSMC(MSMCGains())

    def test_unknown_controller_lists_names(self) -> None:
        with pytest.raises(ValueError, match=r"unknown controller 'pid': valid names are csmc, "):
            make_controller("pid")

    def test_table1_defaults(self) -> None:
        assert CSMCGains().k1 == 3.0
        assert (MSMCGains().k2, MSMCGains().k3) == (3.0, 0.001)
        assert (ASMCGains().mu11, ASMCGains().mu22, ASMCGains().k0) == (0.1, 0.01, 0.2)
        p = ProposedGains()
        assert (p.mu1, p.mu2, p.alpha, p.a, p.b, p.k0) == (3.0, 0.001, 0.1, 0.01, 0.125, 0.2)
        assert (p.lam, p.delta) == (1.0, 0.5)


class TestPolicyMatchesInLoop:
    """A controller run as a policy at control_dt_s = 1 ms reproduces the same controller run
    inside the plant loop.

    The two paths see the same noise: the env draws every plant step's noise row from one
    generator, in order, whatever the decision period, and the policy's measurement (the last
    observation) carries the noise row the in-loop law uses at the next step. They differ only
    by float32 rounding: the observation (speed / 20 rad/s, relative 6e-8, so about 1e-6 rad/s
    and 1e-6 rad) and the action (about 25,000 N m x 6e-8 = 1.5e-3 N m). Through u_eq (gains
    up to 1,241 N m per rad/s) that is a few 1e-3 N m of torque per step (measured: at most
    3e-3 N m, 1.7e-6 rad/s, 1.3e-6 rad over these runs), far below the tolerances (0.05 N m,
    1e-4 rad/s and rad). A wrong noise alignment or an off-by-one step would show up as errors
    of the size of the noise (0.1 rad/s x 1,241 N m s/rad = 124 N m). The 10 s cover the
    start-up stick and the break-away (about 6.3 s).
    """

    SECONDS = 10.0

    def run_pair(self, name: str, noise: float):  # type: ignore[no-untyped-def]
        common = dict(
            randomize=False,
            noise_std_rad_s=noise,
            episode_s=self.SECONDS,
            max_episode_steps=-1,
        )
        in_loop = gym.make("DrillString-v0", base_controller=name, control_dt_s=1.0, **common)
        direct = gym.make("DrillString-v0", control_dt_s=0.001, **common)
        policy = ControllerPolicy.for_env(make_controller(name), direct)
        return rollout(in_loop, ZeroAction(), seed=7), rollout(direct, policy, seed=7)

    @pytest.mark.parametrize("noise", [0.0, 0.1], ids=["noise-off", "noise-on"])
    @pytest.mark.parametrize("name", PAPER)
    def test_same_trajectory(self, name: str, noise: float) -> None:
        a, b = self.run_pair(name, noise)
        assert a.time_s.shape == b.time_s.shape == (10_000,)
        np.testing.assert_allclose(b.torque_nm, a.torque_nm, rtol=0, atol=0.05)
        np.testing.assert_allclose(b.states[:, 0::2], a.states[:, 0::2], rtol=0, atol=1e-4)
        np.testing.assert_allclose(b.states[:, 1::2], a.states[:, 1::2], rtol=0, atol=1e-4)
        np.testing.assert_array_equal(a.bit_stuck, b.bit_stuck)
        assert a.bit_stuck[0] and not a.bit_stuck[-1]  # the run covers the break-away
