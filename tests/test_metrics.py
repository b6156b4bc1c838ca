"""docs/specification.md section 4 metrics on synthetic traces with answers known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drill_env.metrics import METRIC_KEYS, SEVERITY_WINDOW_S, episode_metrics_from_samples

DT = 1e-3


def metrics(w, ref=12.0, u=None, stuck=None, dt=DT):  # type: ignore[no-untyped-def]
    w = np.asarray(w, dtype=float)
    n = w.shape[0]
    ref_a = np.full(n, ref) if np.ndim(ref) == 0 else np.asarray(ref, dtype=float)
    u_a = np.zeros(n) if u is None else np.asarray(u, dtype=float)
    stuck_a = np.zeros(n, dtype=bool) if stuck is None else np.asarray(stuck, dtype=bool)
    return episode_metrics_from_samples(w, ref_a, u_a, stuck_a, dt)


def test_keys() -> None:
    assert set(metrics(np.full(10, 12.0))) == set(METRIC_KEYS)


class TestFirstOrderStep:
    """w(t) = V (1 - exp(-t / tau)), so e(t) = V exp(-t / tau)."""

    V, TAU, T = 12.0, 2.0, 30.0

    @pytest.fixture
    def result(self):  # type: ignore[no-untyped-def]
        t = np.arange(round(self.T / DT)) * DT
        return metrics(self.V * (1 - np.exp(-t / self.TAU)), self.V)

    def test_ise_iae_closed_form(self, result) -> None:  # type: ignore[no-untyped-def]
        v, tau, T = self.V, self.TAU, self.T
        ise = v**2 * tau / 2 * (1 - math.exp(-2 * T / tau))
        iae = v * tau * (1 - math.exp(-T / tau))
        # Left Riemann sums of a decreasing function overshoot by about (e(0) - e(T)) dt / 2.
        assert result["ise"] == pytest.approx(ise, abs=v**2 * DT)
        assert result["iae"] == pytest.approx(iae, abs=v * DT)

    def test_ise_iae_exact_sums(self, result) -> None:  # type: ignore[no-untyped-def]
        # The discrete sums are geometric series: sum r^k over n samples.
        n = round(self.T / DT)
        r1, r2 = math.exp(-DT / self.TAU), math.exp(-2 * DT / self.TAU)
        assert result["iae"] == pytest.approx(self.V * DT * (1 - r1**n) / (1 - r1), rel=1e-9)
        assert result["ise"] == pytest.approx(self.V**2 * DT * (1 - r2**n) / (1 - r2), rel=1e-9)

    def test_rmse(self, result) -> None:  # type: ignore[no-untyped-def]
        assert result["rmse"] == pytest.approx(math.sqrt(result["ise"] / self.T), rel=1e-12)

    def test_no_overshoot(self, result) -> None:  # type: ignore[no-untyped-def]
        assert result["overshoot_pct"] == 0.0

    def test_settling_time(self, result) -> None:  # type: ignore[no-untyped-def]
        # |e| <= 0.05 V from t = tau ln 20 on; the metric gives the first sample time after the
        # last sample outside the band.
        assert result["settling_time_s"] == pytest.approx(self.TAU * math.log(20), abs=DT)


class TestOvershootAndSettling:
    V = 10.0

    def test_step_with_bump(self) -> None:
        # 0 for 2 s, 1.25 V for 1 s, then V: overshoot 25 %, settled from t = 3 s.
        w = np.concatenate([np.zeros(2000), np.full(1000, 1.25 * self.V), np.full(2000, self.V)])
        r = metrics(w, self.V)
        assert r["overshoot_pct"] == pytest.approx(25.0)
        assert r["settling_time_s"] == pytest.approx(3.0)

    def test_band_edge_counts_as_inside(self) -> None:
        w = np.concatenate([np.zeros(1000), np.full(1000, 1.05 * self.V)])
        r = metrics(w, self.V)
        assert r["settling_time_s"] == pytest.approx(1.0)
        assert r["overshoot_pct"] == pytest.approx(5.0)

    def test_never_settles(self) -> None:
        w = np.concatenate([np.full(1000, self.V), np.full(10, 0.9 * self.V)])
        assert metrics(w, self.V)["settling_time_s"] is None

    def test_always_settled(self) -> None:
        assert metrics(np.full(100, self.V), self.V)["settling_time_s"] == 0.0

    def test_overshoot_uses_final_reference(self) -> None:
        # The reference steps from 5 to 10 rad/s; the peak of 12 is 20 % above the final one.
        ref = np.concatenate([np.full(500, 5.0), np.full(500, 10.0)])
        w = np.concatenate([np.full(500, 5.0), np.full(100, 12.0), np.full(400, 10.0)])
        assert metrics(w, ref)["overshoot_pct"] == pytest.approx(20.0)


class TestTorqueMetrics:
    def test_constant_torque(self) -> None:
        r = metrics(np.full(5000, 12.0), u=np.full(5000, 13_000.0))
        assert r["chattering_nm_per_s"] == 0.0
        assert r["rmsd_nm"] == pytest.approx(13_000.0)

    def test_square_wave(self) -> None:
        # Amplitude A, switching every 100 samples over 1 s: 9 switches of A -> 9 A per second.
        a = 500.0
        u = a * ((np.arange(1000) // 100) % 2)
        r = metrics(np.full(1000, 12.0), u=u)
        assert r["chattering_nm_per_s"] == pytest.approx(9 * a / 1.0)
        assert r["rmsd_nm"] == pytest.approx(a / math.sqrt(2))

    def test_alternating_sign(self) -> None:
        u = 200.0 * (-1.0) ** np.arange(2000)  # +-200 every step for 2 s
        r = metrics(np.full(2000, 12.0), u=u)
        assert r["rmsd_nm"] == pytest.approx(200.0)
        assert r["chattering_nm_per_s"] == pytest.approx(1999 * 400.0 / 2.0)


class TestStickSlip:
    def test_sinusoid_severity(self) -> None:
        # Mean m, amplitude A, 0.5 Hz (whole periods in the 20 s window, peaks sampled):
        # severity = (max - min) / (2 mean) = A / m. The earlier 10 s are wild and ignored.
        m, a = 8.0, 6.0
        t = np.arange(20_000) * DT
        tail = m + a * np.sin(2 * np.pi * 0.5 * t)
        head = np.where(np.arange(10_000) % 2 == 0, 0.0, 100.0)
        r = metrics(np.concatenate([head, tail]))
        assert r["stick_slip_severity"] == pytest.approx(a / m, rel=1e-9)

    def test_window_length(self) -> None:
        assert SEVERITY_WINDOW_S == 20.0

    def test_steady_rotation(self) -> None:
        assert metrics(np.full(30_000, 12.0))["stick_slip_severity"] == 0.0

    def test_not_turning(self) -> None:
        assert metrics(np.zeros(30_000))["stick_slip_severity"] == 1.0

    def test_stuck_fraction(self) -> None:
        stuck = np.zeros(4000, dtype=bool)
        stuck[:1000] = True
        assert metrics(np.full(4000, 12.0), stuck=stuck)["stuck_fraction"] == 0.25


class TestValidation:
    def test_empty(self) -> None:
        with pytest.raises(ValueError, match="samples must be non-empty 1-D arrays"):
            episode_metrics_from_samples([], [], [], [], DT)

    def test_shape_mismatch(self) -> None:
        with pytest.raises(ValueError, match=r"got shapes \(3,\), \(2,\), \(3,\), \(3,\)"):
            episode_metrics_from_samples(
                np.zeros(3), np.zeros(2), np.zeros(3), np.zeros(3, dtype=bool), DT
            )

    def test_two_dimensional(self) -> None:
        with pytest.raises(ValueError, match="1-D"):
            episode_metrics_from_samples(
                np.zeros((3, 1)), np.zeros((3, 1)), np.zeros((3, 1)), np.zeros((3, 1)), DT
            )

    @pytest.mark.parametrize("dt", [0.0, -1e-3, math.nan])
    def test_bad_dt(self, dt: float) -> None:
        with pytest.raises(ValueError, match=r"dt_s = .* is out of range: allowed > 0"):
            metrics(np.full(10, 12.0), dt=dt)


def test_interquartile_mean_is_scipys_trimmed_mean() -> None:
    """rliable's IQM is ``scipy.stats.trim_mean(x, 0.25)``: the same values, bit for bit, in
    every shape and along every axis, and a hand-counted case (8 values: the middle 4)."""
    from drill_env.metrics import interquartile_mean

    trim_mean = pytest.importorskip("scipy.stats").trim_mean
    rng = np.random.default_rng(3)
    for n in range(1, 30):
        values = rng.standard_normal((n, 5)) * 10.0 ** rng.integers(-3, 4)
        assert interquartile_mean(values) == trim_mean(values, 0.25, axis=None)
        for axis in (0, 1, -1):
            np.testing.assert_array_equal(
                interquartile_mean(values, axis=axis), trim_mean(values, 0.25, axis=axis)
            )
    assert interquartile_mean([8.0, 1.0, 7.0, 2.0, 6.0, 3.0, 5.0, 100.0]) == 5.25
    with pytest.raises(ValueError, match="no values"):
        interquartile_mean([])
