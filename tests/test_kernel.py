"""The compiled closed-loop engine (:mod:`drill_env.kernel`): what one call writes."""

from __future__ import annotations

import math

import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the built-in env)
from drill_env import kernel
from drill_env.batch import StringBatch
from drill_env.layout import (
    I_NOISE_POS,
    OBS_BOUND,
    REC_BASE_TORQUE,
    REC_REFERENCE,
    REC_STUCK,
    REC_TORQUE,
    REC_X0,
    REP_RESIDUAL_SQUARED,
    REP_STEPS,
    REP_STUCK_STEPS,
    REP_TORQUE_SQUARED,
    REP_TRACKING_SUM,
    REP_VARIATION,
    STATUS_DIVERGED,
    STATUS_OK,
    STATUS_PAUSED,
    X_BIT_SPEED,
)
from drill_env.options import EnvConfig
from drill_env.rewards import tracking_error


def _batch(num: int = 2, **kwargs: object) -> StringBatch:
    config = EnvConfig(randomize=False, control_dt_s=0.05, **kwargs)  # type: ignore[arg-type]
    batch = StringBatch(config, num)
    for i in range(num):
        batch.reset_string(i, i, None)
    return batch


def test_report_sums_are_those_of_the_records() -> None:
    """The reward sums of a call are the sums over the plant steps it recorded."""
    batch = _batch(1, base_controller="proposed", residual_scale_nm=5_000.0)
    last = 0.0
    for action in (0.3, -0.2, 0.0, 1.0):
        batch.step(np.array([action]))
        rec = batch.records[0]
        rep = batch.report[0]
        u = rec[:, REC_TORQUE]
        pairs = zip(rec[:, REC_REFERENCE], rec[:, REC_X0 + X_BIT_SPEED], strict=True)
        tracking = sum(tracking_error(r, w) for r, w in pairs)
        assert rep[REP_TRACKING_SUM] == pytest.approx(tracking, rel=1e-12)
        assert rep[REP_VARIATION] == pytest.approx(np.abs(np.diff(u, prepend=last)).sum())
        assert rep[REP_TORQUE_SQUARED] == pytest.approx(np.sum(u * u))
        added = u - rec[:, REC_BASE_TORQUE]
        assert rep[REP_RESIDUAL_SQUARED] == pytest.approx(np.sum(added * added))
        assert rep[REP_STEPS] == 50 and rep[REP_STUCK_STEPS] == rec[:, REC_STUCK].sum()
        last = u[-1]


def test_a_paused_string_does_not_move() -> None:
    batch = _batch(2)
    batch.step(np.array([0.5, 0.5]))
    before = batch.x.copy()
    batch.status[1] = STATUS_PAUSED
    batch.step(np.array([0.5, 0.5]))
    np.testing.assert_array_equal(batch.x[1], before[1])
    assert np.isnan(batch.records[1]).all() and not np.isnan(batch.records[0]).any()
    assert batch.report[1, REP_STEPS] == 0 and batch.report[1, REP_TRACKING_SUM] == 0


def test_a_diverging_string_keeps_its_last_good_state() -> None:
    """A state beyond the physical bounds is refused: the string stops with status DIVERGED,
    its records after the refused step are NaN and its state stays finite."""
    batch = _batch(1, min_torque_nm=-1e6, max_torque_nm=1e6)
    for _ in range(200):
        batch.step(np.array([1.0]))
        if batch.status[0] != STATUS_OK:
            break
    assert batch.status[0] == STATUS_DIVERGED
    assert np.isfinite(batch.x[0]).all()
    rec = batch.records[0]
    taken = int(batch.report[0, REP_STEPS])
    assert not np.isnan(rec[:taken]).any() and np.isnan(rec[taken + 1 :]).all()


def test_the_noise_block_must_hold_the_call() -> None:
    batch = _batch(1, noise_std_rad_s=0.1)
    batch.arrays.ints[0, I_NOISE_POS] = batch.arrays.noise.shape[1] - 10
    with pytest.raises(ValueError, match="noise block too short"):
        kernel.advance_batch(batch.arrays, batch.settings)


def test_observation_entries_are_scaled_clipped_and_never_nan() -> None:
    out = np.zeros(4, dtype=np.float32)
    sources = np.array([1.0, math.nan, 1e9, -math.inf])
    kernel.write_observation(out, sources, np.arange(4), np.full(4, 0.5))
    np.testing.assert_array_equal(out, [0.5, 0.0, OBS_BOUND, -OBS_BOUND])


def test_the_fast_entry_is_the_compiled_kernel() -> None:
    """The batch calls the kernel's compiled entry point; it gives what the dispatcher gives."""
    a, b = _batch(3, noise_std_rad_s=0.1), _batch(3, noise_std_rad_s=0.1)
    for _ in range(3):
        a.step(np.array([0.1, 0.2, 0.3]))
        b._refill_noise()
        b.command[:] = np.array([0.1, 0.2, 0.3]) * b._action_gain + b._action_offset
        kernel.advance_batch(b.arrays, b.settings)
        np.testing.assert_array_equal(a.records, b.records)
        np.testing.assert_array_equal(a.obs, b.obs)


def test_packed_arrays_run_the_same_kernel() -> None:
    """The packed arrays (addresses and shapes, the batch's fast call) and the arrays
    themselves give the same records, report and observation, bit for bit."""
    a, b = _batch(2, base_controller="proposed"), _batch(2, base_controller="proposed")
    packed = kernel.PackedArrays(a.arrays)
    assert packed.meta.shape == (len(kernel.BatchArrays._fields), 4)
    for action in (0.2, -0.4, 0.0):
        for batch in (a, b):
            batch._refill_noise()
            batch.command[:] = action * batch._action_gain + batch._action_offset
        kernel.advance_batch(packed.meta, a.settings)
        kernel.advance_batch(b.arrays, b.settings)
        for name in ("x", "records", "report", "obs", "law_state"):
            np.testing.assert_array_equal(getattr(a.arrays, name), getattr(b.arrays, name))


def test_packed_arrays_refuse_what_the_kernel_cannot_read() -> None:
    """Packing checks each array's dtype, dimensions and layout, naming the field."""
    arrays = _batch(1).arrays
    with pytest.raises(ValueError, match=r"ints must be a C-contiguous writeable int64 array"):
        kernel.PackedArrays(arrays._replace(ints=arrays.ints.astype(np.float64)))
    with pytest.raises(ValueError, match=r"x must be a C-contiguous writeable float64 array"):
        kernel.PackedArrays(arrays._replace(x=np.zeros((1, 14))[:, ::2]))
    with pytest.raises(ValueError, match=r"records must be .* of 3 dimensions"):
        kernel.PackedArrays(arrays._replace(records=np.zeros((1, 5))))
