"""The engine under both envs (:class:`drill_env.batch.StringBatch`): noise blocks and the
slow path of Python controllers."""

from __future__ import annotations

import numpy as np

import drill_env  # noqa: F401  (registers the built-in env)
from drill_env.batch import StringBatch
from drill_env.layout import SPEED_INDICES, SPEED_SCALE_RAD_S
from drill_env.options import EnvConfig
from drill_env.scenarios import spawn_generators


def test_noise_blocks_are_one_stream_from_the_seed() -> None:
    """The measurement noise of a string is one stream of its own generator, whatever the
    refills: the observation at the end of period k carries row k * substeps of it."""
    config = EnvConfig(randomize=False, noise_std_rad_s=0.5, control_dt_s=0.05)
    batch = StringBatch(config, 1)
    batch.reset_string(0, 123, None)
    rows = batch.arrays.noise.shape[1]
    periods = 3 * rows // config.substeps  # several refills
    stream = spawn_generators(np.random.SeedSequence(123))["noise"].standard_normal(
        (periods * config.substeps + rows, 4)
    )
    for k in range(1, periods + 1):
        batch.step(np.array([0.2]))
        measured = batch.obs[0, list(SPEED_INDICES)].astype(np.float64) * SPEED_SCALE_RAD_S
        true = batch.x[0, list(SPEED_INDICES)]
        expected = true + 0.5 * stream[k * config.substeps]
        np.testing.assert_allclose(measured, expected, rtol=1e-6, atol=1e-5)


class _Wrapped:
    """A built-in controller seen only through the Python protocol (the slow path)."""

    def __init__(self, name: str) -> None:
        self.inner = drill_env.make_controller(name)

    def reset(self) -> None:
        self.inner.reset()

    def torque(self, measurement: np.ndarray, reference_speed_rad_s: float, dt_s: float) -> float:
        return self.inner.torque(measurement, reference_speed_rad_s, dt_s)


def test_slow_path_is_the_compiled_path_without_noise() -> None:
    """A compiled controller driven from Python at every plant step gives the compiled loop's
    trajectory, rewards sums and base torques exactly (no noise: the same measurements)."""
    for name in ("proposed", "z_torque"):
        results = []
        for controller in (name, _Wrapped(name)):
            config = EnvConfig(
                randomize=False, noise_std_rad_s=0.0, base_controller=controller,
                control_dt_s=0.02, wob_n=150e3, reference_speed_rad_s=5.0,
            )  # fmt: skip
            batch = StringBatch(config, 2)
            for i in range(2):
                batch.reset_string(i, i, None)
            out = []
            for a in np.linspace(-0.5, 0.5, 30):
                batch.step(np.array([a, -a]))
                out.append((batch.records.copy(), batch.reward_sums().copy(), batch.x.copy()))
            results.append(out)
        for (rec_c, sums_c, x_c), (rec_p, sums_p, x_p) in zip(*results, strict=True):
            np.testing.assert_array_equal(x_c, x_p)
            np.testing.assert_array_equal(rec_c[..., :12], rec_p[..., :12])
            np.testing.assert_array_equal(sums_c, sums_p)


def test_a_noise_block_is_the_single_draws_of_its_generator() -> None:
    """Drawing a block of normals (``standard_normal(out=...)``, as the noise blocks are
    filled) gives the draws one at a time would, in order, and leaves the generator where
    they would."""
    block_rng, single_rng = (spawn_generators(np.random.SeedSequence(8))["noise"] for _ in "ab")
    block = np.zeros((257, 4))
    block_rng.standard_normal(out=block[1:])
    singles = [single_rng.standard_normal() for _ in range(256 * 4)]
    assert block[1:].ravel().tolist() == singles
    assert block_rng.standard_normal() == single_rng.standard_normal()
