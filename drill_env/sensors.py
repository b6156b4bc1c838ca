"""The measurement channel: what a rig's control system sees of the string, as pure compiled
functions called by the engine at every plant step.

* **Surface signals.** The top-drive speed and the torque at the top of the string are
  sampled every ``sensor_steps`` plant steps (every step by default) with their own noise, and
  held in between.
* **Downhole telemetry.** The bit speed is sampled every ``period_steps`` plant steps (with
  its own noise), delivered ``delay_steps`` later and held until the next delivery; the channel
  reports the last value received and its age. ``period_steps = 0``: no downhole data.

State of one string:

* ``hold`` (``HOLD_*``): the held surface samples and the last sensed plant step;
* ``telemetry`` (``TEL_*``): the last value received, the plant step it was sampled at
  (-1 before the first delivery), and the ring buffer's first slot and count;
* ``buffer``: the samples in flight, ``(capacity, 2)`` rows of (sample step, value), with
  ``capacity >= delay_steps // period_steps + 1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from numba import njit

from drill_env.layout import OBSERVATION_MODES
from drill_env.parameters import PLANT_DT_S
from drill_env.validation import check_choice, check_range

__all__ = [
    "HOLD_LAST_STEP",
    "HOLD_SPEED",
    "HOLD_TORQUE",
    "N_HOLD",
    "N_TELEMETRY",
    "TEL_COUNT",
    "TEL_FIRST",
    "TEL_STEP",
    "TEL_VALUE",
    "MeasurementChannel",
    "reset_channel",
    "sense_surface",
    "sense_telemetry",
    "telemetry_buffer_size",
    "telemetry_reading",
]

HOLD_SPEED: Final = 0  # held top-drive speed sample, rad/s
HOLD_TORQUE: Final = 1  # held surface torque sample, N m
HOLD_LAST_STEP: Final = 2  # the plant step last sensed (each instant is sensed once)
N_HOLD: Final = 3

TEL_VALUE: Final = 0  # the last bit speed received, rad/s (NaN before the first)
TEL_STEP: Final = 1  # the plant step it was sampled at (-1 before the first)
TEL_FIRST: Final = 2  # the oldest sample in flight: its buffer slot
TEL_COUNT: Final = 3  # samples in flight
N_TELEMETRY: Final = 4


@dataclass(frozen=True)
class MeasurementChannel:
    """What the env's measurement channel delivers to a controller, as the env tells a compiled
    controller that asks for it (:func:`drill_env.control.compile_law`): enough to design a
    state observer for it. Built by :meth:`drill_env.options.EnvConfig.measurement_channel`.

    Attributes:
        observation: ``"state"`` (the 4-DOF state is measured) or ``"surface"`` (only the
            surface signals and the telemetry).
        speed_noise_std_rad_s: Noise of the measured speeds, rad/s.
        torque_noise_std_nm: Noise of the measured surface torque, N m.
        sensor_period_s: Sampling period of the surface signals (held in between), s.
        telemetry_period_s: Period of the bit-speed telemetry, s (``None``: no telemetry).
        telemetry_delay_s: Delay from a telemetry sample to its delivery, s.
        telemetry_noise_std_rad_s: Noise of the telemetry's bit speed, rad/s.
    """

    observation: str
    speed_noise_std_rad_s: float
    torque_noise_std_nm: float
    sensor_period_s: float = PLANT_DT_S
    telemetry_period_s: float | None = None
    telemetry_delay_s: float = 0.0
    telemetry_noise_std_rad_s: float = 0.0

    def __post_init__(self) -> None:
        check_choice("observation", self.observation, OBSERVATION_MODES, "mode")
        check_range("speed_noise_std_rad_s", self.speed_noise_std_rad_s, 0.0, 10.0)
        check_range("torque_noise_std_nm", self.torque_noise_std_nm, 0.0, 1e5)
        check_range("sensor_period_s", self.sensor_period_s, PLANT_DT_S, 10.0)
        if self.telemetry_period_s is not None:
            check_range("telemetry_period_s", self.telemetry_period_s, PLANT_DT_S, 600.0)
        check_range("telemetry_delay_s", self.telemetry_delay_s, 0.0, 600.0)
        check_range("telemetry_noise_std_rad_s", self.telemetry_noise_std_rad_s, 0.0, 10.0)


def telemetry_buffer_size(period_steps: int, delay_steps: int) -> int:
    """Slots the telemetry buffer needs: the samples in flight at once, plus one."""
    return 1 if period_steps <= 0 else delay_steps // period_steps + 2


@njit(cache=True)
def reset_channel(hold, telemetry) -> None:
    """The channel of a string at the start of an episode: nothing sensed, nothing received."""
    hold[HOLD_SPEED] = 0.0
    hold[HOLD_TORQUE] = 0.0
    hold[HOLD_LAST_STEP] = -1.0
    telemetry[TEL_VALUE] = math.nan
    telemetry[TEL_STEP] = -1.0
    telemetry[TEL_FIRST] = 0.0
    telemetry[TEL_COUNT] = 0.0


@njit(cache=True, inline="always")
def sense_surface(hold, k: int, sensor_steps: int, speed: float, torque: float) -> bool:
    """Take the surface samples of plant step ``k`` (measured top-drive speed, rad/s, and
    surface torque, N m, noise included) when ``k`` is a sampling instant; each instant is
    sensed once. Returns whether ``k`` had not been sensed before."""
    if hold[HOLD_LAST_STEP] == k:
        return False
    hold[HOLD_LAST_STEP] = k
    if sensor_steps == 1 or k % sensor_steps == 0:
        hold[HOLD_SPEED] = speed
        hold[HOLD_TORQUE] = torque
    return True


@njit(cache=True, inline="always")
def sense_telemetry(
    telemetry, buffer, k: int, period_steps: int, delay_steps: int, bit_speed: float
) -> None:
    """Telemetry at plant step ``k``: sample the (noisy) ``bit_speed`` (rad/s) when ``k`` is a
    sampling instant, then deliver every sample whose delay has passed. Call once per instant."""
    if period_steps <= 0:
        return
    size = buffer.shape[0]
    first = int(telemetry[TEL_FIRST])
    count = int(telemetry[TEL_COUNT])
    if k % period_steps == 0:
        slot = (first + count) % size
        buffer[slot, 0] = k
        buffer[slot, 1] = bit_speed
        if count < size:
            count += 1
        else:  # cannot happen with telemetry_buffer_size slots; drop the oldest
            first = (first + 1) % size
    while count > 0 and buffer[first, 0] + delay_steps <= k:
        telemetry[TEL_STEP] = buffer[first, 0]
        telemetry[TEL_VALUE] = buffer[first, 1]
        first = (first + 1) % size
        count -= 1
    telemetry[TEL_FIRST] = first
    telemetry[TEL_COUNT] = count


@njit(cache=True, inline="always")
def telemetry_reading(telemetry, k: int, dt: float):
    """``(value, age)`` at plant step ``k``: the last bit speed received (rad/s) and the time
    since it was sampled (s); ``(nan, nan)`` before the first delivery."""
    if telemetry[TEL_STEP] < 0:
        return math.nan, math.nan
    return telemetry[TEL_VALUE], (k - telemetry[TEL_STEP]) * dt
