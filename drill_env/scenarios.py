"""The scenario of an episode and every random draw: WOB profile, reference-speed profile,
parametric uncertainty (docs/specification.md section 2, the paper's Table 3) and measurement
noise.

:class:`Scenario` is the one description of what is exogenous about an episode: the env builds
one from its keywords or draws one from :class:`Randomization`, and studies describe their
runs as scenarios (``gym.make(..., **scenario.keywords())``).

Each random component draws from its own ``np.random.Generator``; :func:`spawn_generators`
makes them from one ``np.random.SeedSequence``, so an episode's draws do not depend on how
many numbers another component used.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.distributed import (
    DistributedStringParameters,
    resolve_distributed_parameters,
    with_measured_depth,
)
from drill_env.limits import MAX_MEASURED_DEPTH_M, MAX_REFERENCE_RAD_S, MAX_WOB_N
from drill_env.parameters import DrillStringParameters, resolve_parameters, scale_uncertain
from drill_env.validation import check_choice, check_interval, check_range, shown

__all__ = [
    "COMPONENTS",
    "CarriedSeedSequence",
    "FieldRandomization",
    "READINGS",
    "UNCERTAINTY_CONDITIONS",
    "Randomization",
    "Scenario",
    "SpeedProfile",
    "UncertaintyReading",
    "WobProfile",
    "carried_seed_sequence",
    "knot_arrays",
    "profile_value",
    "resolve_uncertainty",
    "spawn_generators",
]


@njit(cache=True)
def profile_value(times, values, n: int, t: float) -> float:
    """Value at time ``t`` (s) of the piecewise-linear profile through the first ``n`` knots
    ``(times, values)``: constant outside them, a repeated knot time is a step (right-continuous).
    Compiled, so that the plant loop reads WOB and reference profiles at every step."""
    if n == 1 or t <= times[0]:
        return values[0]
    j = 0
    while j + 1 < n and t >= times[j + 1]:
        j += 1
    if j == n - 1:
        return values[n - 1]
    span = times[j + 1] - times[j]
    return values[j] + (values[j + 1] - values[j]) * (t - times[j]) / span


MAX_KNOTS: Final = 16
"""Largest number of knots of a profile."""

UNCERTAINTY_CONDITIONS: Final[dict[str, tuple[float, float, float]]] = {
    "nominal": (0.0, 0.0, 0.0),
    "condition1": (0.40, 0.30, 0.30),
    "condition2": (0.60, 0.50, 0.40),
    "condition3": (0.75, 0.75, 0.75),
}
"""Table 3: relative increases (Delta1 of c_pi, Delta2 of k_pi, Delta3 of c_dt)."""

UncertaintyReading = Literal["plant", "controller"]
READINGS: Final = ("plant", "controller")
"""The two readings of the uncertainty: scale the true plant, or the controllers' model."""
COMPONENTS: Final = ("wob", "reference", "uncertainty", "noise")
"""The random components, in the order their generators are spawned."""


@dataclass(frozen=True)
class WobProfile:
    """Weight on bit: constant, or with one step change (a new rock layer).

    Attributes:
        initial_n: WOB from t = 0, N (> 0).
        step_time_s: Time of the step change, s; ``None`` for a constant WOB.
        final_n: WOB after the step, N (> 0); required with ``step_time_s``.
    """

    initial_n: float
    step_time_s: float | None = None
    final_n: float | None = None

    def __post_init__(self) -> None:
        check_range("wob_n", self.initial_n, 1e-9, MAX_WOB_N)
        if (self.step_time_s is None) != (self.final_n is None):
            raise ValueError("wob_step_time_s and wob_final_n must be given together")
        if self.step_time_s is not None and self.final_n is not None:
            check_range("wob_step_time_s", self.step_time_s, 0.0, math.inf)
            check_range("wob_final_n", self.final_n, 1e-9, MAX_WOB_N)

    def knots(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Knot times (s) and values (N) of the piecewise-linear profile."""
        if self.step_time_s is None or self.final_n is None:
            return (0.0,), (float(self.initial_n),)
        t = float(self.step_time_s)
        return (t, t), (float(self.initial_n), float(self.final_n))


@dataclass(frozen=True)
class SpeedProfile:
    """Reference bit speed through piecewise-linear knots (rad/s); a repeated time is a step.

    Use :meth:`constant`, :meth:`steps` or :meth:`ramp` rather than the knots directly.
    """

    times_s: tuple[float, ...]
    values_rad_s: tuple[float, ...]

    def __post_init__(self) -> None:
        if not 1 <= len(self.times_s) == len(self.values_rad_s) <= MAX_KNOTS:
            raise ValueError(
                f"reference profile needs 1 to {MAX_KNOTS} knots with one value per time, got "
                f"{len(self.times_s)} times and {len(self.values_rad_s)} values"
            )
        times, values = [], []
        for k, (t, v) in enumerate(zip(self.times_s, self.values_rad_s, strict=True)):
            times.append(check_range(f"reference time[{k}]", t, 0.0, math.inf))
            values.append(check_range(f"reference_speed_rad_s[{k}]", v, 0.0, MAX_REFERENCE_RAD_S))
        object.__setattr__(self, "times_s", tuple(times))  # as floats
        object.__setattr__(self, "values_rad_s", tuple(values))
        if any(b < a for a, b in zip(self.times_s, self.times_s[1:], strict=False)):
            raise ValueError(f"reference knot times must not decrease, got {shown(self.times_s)}")

    @classmethod
    def constant(cls, speed_rad_s: float) -> SpeedProfile:
        """A constant reference, rad/s."""
        return cls((0.0,), (speed_rad_s,))  # checked by __post_init__

    @classmethod
    def steps(cls, initial_rad_s: float, changes: Sequence[tuple[float, float]]) -> SpeedProfile:
        """Start at ``initial_rad_s`` and jump to ``v`` at each ``(t, v)`` of ``changes``."""
        times: list[float] = [0.0]
        values: list[float] = [initial_rad_s]
        for t, v in itertools.islice(changes, MAX_KNOTS):  # more are refused by the knot count
            times += [t, t]
            values += [values[-1], v]
        return cls(tuple(times), tuple(values))  # checked by __post_init__

    @classmethod
    def ramp(cls, start_rad_s: float, end_rad_s: float, t0_s: float, t1_s: float) -> SpeedProfile:
        """Hold ``start_rad_s`` until ``t0_s``, ramp linearly to ``end_rad_s`` at ``t1_s``."""
        t0 = check_range("ramp start time", t0_s, 0.0, math.inf)
        t1 = check_range("ramp end time", t1_s, 0.0, math.inf)
        if not t1 > t0:
            raise ValueError(
                f"ramp end time {shown(t1_s)} must be after its start time {shown(t0_s)}"
            )
        return cls((t0, t1), (start_rad_s, end_rad_s))  # checked by __post_init__

    def value(self, t_s: float) -> float:
        """Reference speed at time ``t_s``, rad/s."""
        times, values, n = knot_arrays(self)
        return float(profile_value(times, values, n, float(t_s)))


def resolve_uncertainty(value: str | Sequence[float]) -> tuple[float, float, float]:
    """Table 3 condition name or an explicit ``(Delta1, Delta2, Delta3)``, each in [-0.9, 10]."""
    if isinstance(value, str):
        try:
            return UNCERTAINTY_CONDITIONS[value]
        except KeyError:
            raise ValueError(
                f"uncertainty = {shown(value)} is not a known condition: allowed "
                f"{sorted(UNCERTAINTY_CONDITIONS)} or a (Delta1, Delta2, Delta3) tuple"
            ) from None
    try:
        deltas = tuple(itertools.islice(value, 4))  # a longer iterable is refused unread
    except TypeError:
        raise TypeError(
            f"uncertainty must be a condition name or 3 numbers, got {shown(value)}"
        ) from None
    if len(deltas) != 3:
        got = "more" if len(deltas) > 3 else len(deltas)
        raise ValueError(f"uncertainty must have 3 entries (Delta1..3), got {got}")
    d1, d2, d3 = (check_range(f"uncertainty[{k}]", d, -0.9, 10.0) for k, d in enumerate(deltas))
    return (d1, d2, d3)


def _draw_wob_and_reference(
    generators: dict[str, np.random.Generator],
    episode_s: float,
    wob_range_n: tuple[float, float],
    wob_step_probability: float,
    wob_step_time_fraction: tuple[float, float],
    reference_range_rad_s: tuple[float, float],
) -> tuple[WobProfile, SpeedProfile]:
    """A WOB profile (uniform, with one step change at the given chance) and a constant
    reference speed, each from its own generator."""
    g = generators["wob"]
    wob0 = float(g.uniform(*wob_range_n))
    step_time: float | None = None
    wob1: float | None = None
    if g.random() < wob_step_probability:
        step_time = float(g.uniform(*wob_step_time_fraction)) * episode_s
        wob1 = float(g.uniform(*wob_range_n))
    ref = float(generators["reference"].uniform(*reference_range_rad_s))
    return WobProfile(wob0, step_time, wob1), SpeedProfile.constant(ref)


@dataclass(frozen=True)
class Randomization:
    """Ranges of the per-episode draws of ``DrillString-v0`` (uniform unless stated).

    Attributes:
        wob_range_n: Range of the WOB, N.
        wob_step_probability: Chance of one WOB step change per episode, in [0, 1].
        wob_step_time_fraction: Range of the step time as a fraction of the episode.
        reference_range_rad_s: Range of the constant reference bit speed, rad/s.
        delta_range: Range of each of Delta1..3 (relative increase of c_pi, k_pi, c_dt).
    """

    wob_range_n: tuple[float, float] = (60e3, 200e3)
    wob_step_probability: float = 0.5
    wob_step_time_fraction: tuple[float, float] = (0.5, 0.5)
    reference_range_rad_s: tuple[float, float] = (4.0, 16.0)
    delta_range: tuple[float, float] = (0.0, 0.75)

    def __post_init__(self) -> None:
        check_interval("wob_range_n", self.wob_range_n, 1e-9, MAX_WOB_N)
        check_range("wob_step_probability", self.wob_step_probability, 0.0, 1.0)
        check_interval("wob_step_time_fraction", self.wob_step_time_fraction, 0.0, 1.0)
        check_interval(
            "reference_range_rad_s", self.reference_range_rad_s, 0.0, MAX_REFERENCE_RAD_S
        )
        check_interval("delta_range", self.delta_range, -0.9, 10.0)

    def draw(
        self,
        generators: dict[str, np.random.Generator],
        episode_s: float,
        parameters: DrillStringParameters,
        reading: UncertaintyReading,
        noise_std_rad_s: float,
    ) -> Scenario:
        """A scenario drawn from these ranges, each component from its own generator."""
        wob, reference = _draw_wob_and_reference(
            generators,
            episode_s,
            self.wob_range_n,
            self.wob_step_probability,
            self.wob_step_time_fraction,
            self.reference_range_rad_s,
        )
        lo, hi = self.delta_range
        d = generators["uncertainty"].uniform(lo, hi, size=3)
        return Scenario(
            wob=wob,
            reference=reference,
            uncertainty=(float(d[0]), float(d[1]), float(d[2])),
            reading=reading,
            noise_std_rad_s=noise_std_rad_s,
            parameters=parameters,
        )


RPM: Final = 2.0 * math.pi / 60.0
"""One revolution per minute in rad/s."""


@dataclass(frozen=True)
class FieldRandomization:
    """Ranges of the per-episode draws of ``DrillStringField-v0`` (uniform; the sources and
    the reasons are in docs/specification.md section 18).

    Attributes:
        wob_range_n: Range of the WOB, N.
        wob_step_probability: Chance of one WOB step change (a new rock layer) per episode.
        wob_step_time_fraction: Range of the step time as a fraction of the episode.
        reference_range_rad_s: Range of the constant reference bit speed, rad/s (40-160 rpm).
        measured_depth_range_m: Range of the measured depth, m: the drill pipe is made longer
            or shorter, the BHA kept (``drill_env.distributed.with_measured_depth``).
        mu_a_range: Range of the static friction coefficient.
        mu_0_ratio_range: Range of ``mu_0 / mu_a``, in (0, 1].
        xi_range: Range of the Stribeck decline rate, s/rad.
        mud_damping_factor_range: Range of the factor on the mud damping rate.
    """

    wob_range_n: tuple[float, float] = (50e3, 200e3)
    wob_step_probability: float = 0.5
    wob_step_time_fraction: tuple[float, float] = (0.2, 0.8)
    reference_range_rad_s: tuple[float, float] = (40 * RPM, 160 * RPM)
    measured_depth_range_m: tuple[float, float] = (1_000.0, 5_000.0)
    mu_a_range: tuple[float, float] = (0.6, 1.0)
    mu_0_ratio_range: tuple[float, float] = (0.5, 0.8)
    xi_range: tuple[float, float] = (0.3, 1.0)
    mud_damping_factor_range: tuple[float, float] = (0.5, 2.0)

    def __post_init__(self) -> None:
        check_interval("wob_range_n", self.wob_range_n, 1e-9, MAX_WOB_N)
        check_range("wob_step_probability", self.wob_step_probability, 0.0, 1.0)
        check_interval("wob_step_time_fraction", self.wob_step_time_fraction, 0.0, 1.0)
        check_interval(
            "reference_range_rad_s", self.reference_range_rad_s, 0.0, MAX_REFERENCE_RAD_S
        )
        check_interval(
            "measured_depth_range_m", self.measured_depth_range_m, 1.0, MAX_MEASURED_DEPTH_M
        )
        check_interval("mu_a_range", self.mu_a_range, 1e-3, 10.0)
        check_interval("mu_0_ratio_range", self.mu_0_ratio_range, 1e-3, 1.0)
        check_interval("xi_range", self.xi_range, 0.0, 100.0)
        check_interval("mud_damping_factor_range", self.mud_damping_factor_range, 0.0, 100.0)

    def string(
        self, parameters: DistributedStringParameters, g: np.random.Generator
    ) -> tuple[DistributedStringParameters, DistributedStringParameters]:
        """A drawn string and its nominal twin at the same depth (what the controllers know:
        the geometry, with the nominal friction and damping)."""
        depth = float(g.uniform(*self.measured_depth_range_m))
        mu_a = float(g.uniform(*self.mu_a_range))
        ratio = float(g.uniform(*self.mu_0_ratio_range))
        xi = float(g.uniform(*self.xi_range))
        factor = float(g.uniform(*self.mud_damping_factor_range))
        nominal = with_measured_depth(parameters, depth)
        damping = dataclasses.replace(
            nominal.damping, mud_rate_per_s=nominal.damping.mud_rate_per_s * factor
        )
        plant = dataclasses.replace(nominal, mu_a=mu_a, mu_0=ratio * mu_a, xi=xi, damping=damping)
        return plant, nominal

    def draw(
        self,
        generators: dict[str, np.random.Generator],
        episode_s: float,
        parameters: DistributedStringParameters,
        noise_std_rad_s: float,
    ) -> Scenario:
        """A scenario drawn from these ranges, each component from its own generator (the
        string from the ``uncertainty`` one)."""
        wob, reference = _draw_wob_and_reference(
            generators,
            episode_s,
            self.wob_range_n,
            self.wob_step_probability,
            self.wob_step_time_fraction,
            self.reference_range_rad_s,
        )
        plant, nominal = self.string(
            resolve_distributed_parameters(parameters), generators["uncertainty"]
        )
        return Scenario(
            wob=wob,
            reference=reference,
            noise_std_rad_s=noise_std_rad_s,
            parameters=plant,
            model=nominal,
        )


# numpy's SeedSequence hash (O'Neill's seed_seq alternative, as numpy documents it): constants.
_POOL_WORDS: Final = 4  # numpy's default pool size, 32-bit words
_INIT_A: Final = 0x43B0D7E5
_MULT_A: Final = 0x931E8875
_INIT_B: Final = 0x8B51F9DD
_MULT_B: Final = 0x58F38DED
_MIX_MULT_L: Final = 0xCA01F9DD
_MIX_MULT_R: Final = 0x4973F715
_MASK32: Final = 0xFFFFFFFF


def _words(value: object) -> list[int] | None:
    """An int, or a sequence of ints, as numpy's SeedSequence reads it: 32-bit words, least
    significant first (0 is one word); None for anything else (then numpy's own is used)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        n = int(value)
        if n < 0:
            return None
        words = [n & _MASK32]
        n >>= 32
        while n:
            words.append(n & _MASK32)
            n >>= 32
        return words
    if isinstance(value, (tuple, list)):
        words = []
        for item in value:
            part = _words(item)
            if part is None:
                return None
            words += part
        return words
    return None


def _absorb(pool: list[int], hash_const: int, word: int) -> int:
    """Mix one more entropy ``word`` into every word of ``pool`` (in place), as numpy's
    SeedSequence does with the words past its pool size; returns the new hash constant."""
    for i in range(_POOL_WORDS):
        value = word ^ hash_const
        hash_const = (hash_const * _MULT_A) & _MASK32
        value = (value * hash_const) & _MASK32
        value ^= value >> 16
        mixed = (_MIX_MULT_L * pool[i] - _MIX_MULT_R * value) & _MASK32
        pool[i] = mixed ^ (mixed >> 16)
    return hash_const


class CarriedSeedSequence(np.random.bit_generator.ISpawnableSeedSequence):
    """numpy's :class:`numpy.random.SeedSequence`, with the hash of its entropy carried
    forward: a child costs the same whatever the depth of its spawn key.

    numpy hashes a sequence's entropy words, then its spawn key's, into its pool one after the
    other; a child's words are its parent's plus its own index. This class keeps the pool and
    the hash constant after its words, so that :meth:`spawn` hashes one word per child instead
    of the whole key (numpy's cost grows with the key: about 2 us per word, per sequence).
    :meth:`generate_state` and :meth:`spawn` give what numpy's would, bit for bit (checked
    against numpy in the tests); build one with :func:`carried_seed_sequence`.
    """

    __slots__ = ("_hash_const", "_pool", "depth", "n_children_spawned")

    def __init__(self, pool: list[int], hash_const: int, depth: int) -> None:
        self._pool = pool
        self._hash_const = hash_const
        self.depth = depth
        """Length of the spawn key (the generations below the root sequence)."""
        self.n_children_spawned = 0
        """How many children :meth:`spawn` made so far (the next child's index)."""

    @property
    def pool(self) -> npt.NDArray[np.uint32]:
        """The hashed pool, (4,) uint32 (numpy's ``SeedSequence.pool``)."""
        return np.array(self._pool, dtype=np.uint32)

    def generate_state(
        self, n_words: int, dtype: npt.DTypeLike = np.uint32
    ) -> npt.NDArray[np.uint32 | np.uint64]:
        """``n_words`` words of state of ``dtype`` (uint32 or uint64), as numpy's
        ``SeedSequence.generate_state``."""
        wide = np.dtype(dtype) == np.dtype(np.uint64)
        if not wide and np.dtype(dtype) != np.dtype(np.uint32):
            raise ValueError("only support uint32 or uint64")
        hash_const = _INIT_B
        pool = self._pool
        words = []
        for i in range(2 * n_words if wide else n_words):
            value = pool[i % _POOL_WORDS] ^ hash_const
            hash_const = (hash_const * _MULT_B) & _MASK32
            value = (value * hash_const) & _MASK32
            words.append(value ^ (value >> 16))
        if wide:  # numpy's uint64 words are pairs of uint32 words, least significant first
            return np.array(
                [low | high << 32 for low, high in zip(words[::2], words[1::2], strict=True)],
                dtype=np.uint64,
            )
        return np.array(words, dtype=np.uint32)

    def spawn(self, n_children: int) -> list[CarriedSeedSequence]:
        """The next ``n_children`` children, as numpy's ``SeedSequence.spawn``."""
        children = []
        for index in range(self.n_children_spawned, self.n_children_spawned + n_children):
            pool = list(self._pool)
            hash_const = self._hash_const
            for word in _words(index) or ():
                hash_const = _absorb(pool, hash_const, word)
            children.append(CarriedSeedSequence(pool, hash_const, self.depth + 1))
        self.n_children_spawned += n_children
        return children


def carried_seed_sequence(
    sequence: np.random.SeedSequence,
) -> CarriedSeedSequence | np.random.SeedSequence:
    """``sequence`` as a :class:`CarriedSeedSequence` (its children numpy's, bit for bit), or
    ``sequence`` itself when its entropy is not ints or numpy's pool differs from the hash
    computed here (another pool size, or another hash in some numpy version)."""
    entropy = _words(sequence.entropy)
    key = _words(list(sequence.spawn_key))
    if entropy is None or key is None or sequence.pool_size != _POOL_WORDS:
        return sequence
    if key and len(entropy) < _POOL_WORDS:  # with a spawn key, numpy pads the entropy
        entropy += [0] * (_POOL_WORDS - len(entropy))
    words = entropy + key
    pool = [0] * _POOL_WORDS
    hash_const = _INIT_A
    for i in range(_POOL_WORDS):  # fill the pool
        value = (words[i] if i < len(words) else 0) ^ hash_const
        hash_const = (hash_const * _MULT_A) & _MASK32
        value = (value * hash_const) & _MASK32
        pool[i] = value ^ (value >> 16)
    for source in range(_POOL_WORDS):  # mix every pool word into every other
        for target in range(_POOL_WORDS):
            if source != target:
                value = pool[source] ^ hash_const
                hash_const = (hash_const * _MULT_A) & _MASK32
                value = (value * hash_const) & _MASK32
                value ^= value >> 16
                mixed = (_MIX_MULT_L * pool[target] - _MIX_MULT_R * value) & _MASK32
                pool[target] = mixed ^ (mixed >> 16)
    for word in words[_POOL_WORDS:]:  # then the rest of the words, one at a time
        hash_const = _absorb(pool, hash_const, word)
    if pool != sequence.pool.tolist():
        return sequence
    result = CarriedSeedSequence(pool, hash_const, len(sequence.spawn_key))
    result.n_children_spawned = sequence.n_children_spawned
    return result


def spawn_generators(
    seed_sequence: np.random.bit_generator.ISpawnableSeedSequence,
) -> dict[str, np.random.Generator]:
    """One generator per random component (:data:`COMPONENTS`) from ``seed_sequence``, plus
    two streams of the measurement channel spawned from the ``noise`` component's sequence:
    ``sensors`` (surface torque and telemetry noise) and ``nodes`` (a distributed string's
    node-speed noise), so that adding them changes none of the other draws."""
    children = seed_sequence.spawn(len(COMPONENTS))
    generators = {
        name: np.random.default_rng(child) for name, child in zip(COMPONENTS, children, strict=True)
    }
    sensors, nodes = children[COMPONENTS.index("noise")].spawn(2)
    generators["sensors"] = np.random.default_rng(sensors)
    generators["nodes"] = np.random.default_rng(nodes)
    return generators


@dataclass(frozen=True)
class Scenario:
    """Everything exogenous about one episode, resolved to numbers.

    Attributes:
        wob: WOB profile.
        reference: Reference bit-speed profile.
        uncertainty: ``(Delta1, Delta2, Delta3)``, relative increases of ``c_pi``, ``k_pi`` and
            ``c_dt`` (the paper's Table 3).
        reading: ``"plant"``: the plant carries the uncertainty; ``"controller"``: the
            controllers' model does.
        noise_std_rad_s: Measurement noise on the speeds, rad/s.
        parameters: Nominal plant parameters: a 4-DOF set, or a distributed string (then the
            true plant itself).
        model: A distributed string's parameters as the controllers know them (``None``: the
            plant's); not used with a 4-DOF plant, whose model follows from the uncertainty.
        plant: The true plant's parameters (derived).
        controller_model: The parameters the controllers' model uses (derived).
    """

    wob: WobProfile
    reference: SpeedProfile
    uncertainty: tuple[float, float, float] = (0.0, 0.0, 0.0)
    reading: UncertaintyReading = "plant"
    noise_std_rad_s: float = 0.0
    parameters: DrillStringParameters | DistributedStringParameters = field(
        default_factory=DrillStringParameters
    )
    model: DistributedStringParameters | None = None
    plant: DrillStringParameters | DistributedStringParameters = field(
        init=False, repr=False, compare=False
    )
    controller_model: DrillStringParameters | DistributedStringParameters = field(
        init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if not isinstance(self.wob, WobProfile):
            raise TypeError(f"wob must be a WobProfile, got {shown(self.wob)}")
        if not isinstance(self.reference, SpeedProfile):
            raise TypeError(f"reference must be a SpeedProfile, got {shown(self.reference)}")
        object.__setattr__(self, "uncertainty", resolve_uncertainty(self.uncertainty))
        check_choice("uncertainty_reading", self.reading, READINGS, "reading")
        check_range("noise_std_rad_s", self.noise_std_rad_s, 0.0, 10.0)
        if isinstance(self.parameters, DistributedStringParameters):
            if any(self.uncertainty):
                raise ValueError(
                    f"uncertainty = {shown(self.uncertainty)} is out of range for a distributed "
                    "string: allowed (0, 0, 0) (the conditions scale the 4-DOF plant)"
                )
            if self.model is not None and not isinstance(self.model, DistributedStringParameters):
                raise TypeError(
                    f"model must be a DistributedStringParameters, got {type(self.model).__name__}"
                )
            object.__setattr__(self, "plant", self.parameters)
            object.__setattr__(self, "controller_model", self.model or self.parameters)
            return
        if self.model is not None:
            raise ValueError("model is for a distributed string; a 4-DOF model follows from "
                             "uncertainty and reading")  # fmt: skip
        object.__setattr__(self, "parameters", resolve_parameters(self.parameters))
        scaled = scale_uncertain(self.parameters, self.uncertainty)
        plant, model = (
            (scaled, self.parameters) if self.reading == "plant" else (self.parameters, scaled)
        )
        object.__setattr__(self, "plant", plant)
        object.__setattr__(self, "controller_model", model)

    @property
    def distributed(self) -> bool:
        """Whether the plant is a distributed string."""
        return isinstance(self.parameters, DistributedStringParameters)

    def keywords(self) -> dict[str, Any]:
        """The env keywords (and ``reset`` options) that give this scenario: those of
        ``DrillString-v0``, or of ``DrillStringField-v0`` for a distributed string."""
        ref = self.reference
        constant = len(ref.times_s) == 1
        common = {
            "randomize": False,
            "parameters": self.parameters,
            "wob_n": self.wob.initial_n,
            "wob_step_time_s": self.wob.step_time_s,
            "wob_final_n": self.wob.final_n,
            "reference_speed_rad_s": ref.values_rad_s[0] if constant else ref,
            "noise_std_rad_s": self.noise_std_rad_s,
        }
        if self.distributed:
            return {**common, "measured_depth_m": None, "controller_parameters": self.model}
        return {**common, "uncertainty": self.uncertainty, "uncertainty_reading": self.reading}


def knot_arrays(
    profile: WobProfile | SpeedProfile,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], int]:
    """Knot times and values padded to :data:`MAX_KNOTS`, and the knot count."""
    times, values = (
        profile.knots()
        if isinstance(profile, WobProfile)
        else (profile.times_s, profile.values_rad_s)
    )
    t = np.zeros(MAX_KNOTS)
    v = np.zeros(MAX_KNOTS)
    t[: len(times)] = times
    v[: len(values)] = values
    return t, v, len(times)
