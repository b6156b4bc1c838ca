"""Torsional modes and impedances of the lumped drill string, for tuning top-drive controllers.

The industry stick-slip controllers (:mod:`baselines.soft_speed`, :mod:`baselines.z_torque`) are
tuned from two numbers of the string: its lowest torsional natural frequency with the bit stuck
(the *stick-slip frequency*) and the *characteristic impedance* of the drill pipe. For a real,
continuous pipe they come from wave mechanics; here they are computed from the 4-DOF lumped
model of docs/specification.md section 1, in plain numpy (never inside the compiled loop).

Characteristic impedance. A uniform pipe of length ``L``, polar moment ``I_p``, shear modulus
``G`` and density ``rho`` has the torsional wave impedance ``zeta = I_p sqrt(G rho)`` (torque
per unit angular speed of a travelling wave; Kyllingstad & Halsey 1988; Dwars 2015). Its total
torsional stiffness is ``k = G I_p / L`` and its total inertia ``J = rho I_p L``, so
``sqrt(k J) = I_p sqrt(G rho) = zeta`` exactly: the impedance of a pipe is the geometric mean
of its lumped stiffness and inertia. The lumped model keeps the drill pipe as one inertia
``J_pi`` behind one spring ``k_pi`` from the top drive, so its pipe impedance is
``Z = sqrt(k_pi J_pi)`` (1,393.6 N m s/rad for ``zribi2024``). The one-way travel time of a
torsional wave along that pipe is ``sqrt(J_pi / k_pi)`` (2.0 s).

Stick-slip frequency. While the bit is stuck the string is a chain of inertias between the top
drive and a fixed bit. A stiff (speed-controlled) top drive also holds its end still for
perturbations, so the string oscillates in its lowest *clamped-top, stuck-bit* mode; that is
the frequency a stick-slip cycle rings at (for a uniform pipe, the quarter-wave mode
``pi / (2 L / c)``; Kyllingstad & Halsey 1988). For ``zribi2024`` it is 0.626 rad/s
(period 10.0 s). The generalised eigenproblem ``K v = w^2 M v`` of the undamped linear string
is solved for any of the end conditions below.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal, NamedTuple, overload

import numpy as np
import numpy.typing as npt

from drill_env.distributed import DistributedStringParameters
from drill_env.modes import lumped_equivalent, stick_slip_frequency_rad_s
from drill_env.modes import pipe_impedance as distributed_pipe_impedance
from drill_env.parameters import DrillStringParameters, resolve_parameters
from drill_env.validation import shown

__all__ = [
    "BIT_ENDS",
    "TOP_ENDS",
    "StringModes",
    "StringView",
    "pipe_impedance",
    "pipe_travel_time_s",
    "reflection_coefficient",
    "stick_slip_frequency",
    "string_modes",
    "string_view",
    "top_drive_impedance",
]

TopEnd = Literal["clamped", "free"]
BitEnd = Literal["stuck", "free"]
TOP_ENDS: Final = ("clamped", "free")
BIT_ENDS: Final = ("stuck", "free")


@dataclass(frozen=True)
class StringModes:
    """Undamped torsional modes of the lumped string for one pair of end conditions.

    Attributes:
        top: ``"clamped"`` (top-drive speed held) or ``"free"`` (top drive a free inertia).
        bit: ``"stuck"`` (bit held by static friction) or ``"free"`` (bit a free inertia).
        dofs: Names of the moving inertias, top to bottom.
        frequencies_rad_s: Natural angular frequencies, ascending, rad/s (rigid-body modes of a
            free-free string are left out).
        shapes: Mode shapes, one column per frequency, scaled so that the largest amplitude
            is +1.
    """

    top: str
    bit: str
    dofs: tuple[str, ...]
    frequencies_rad_s: npt.NDArray[np.float64]
    shapes: npt.NDArray[np.float64]

    @property
    def lowest_rad_s(self) -> float:
        """The lowest natural frequency, rad/s."""
        return float(self.frequencies_rad_s[0])

    @property
    def periods_s(self) -> npt.NDArray[np.float64]:
        """Natural periods ``2 pi / w``, s."""
        return 2.0 * np.pi / self.frequencies_rad_s


def string_modes(
    params: DrillStringParameters | str = "zribi2024",
    top: TopEnd = "clamped",
    bit: BitEnd = "stuck",
) -> StringModes:
    """Natural frequencies and shapes of the undamped linear string, ``K v = w^2 M v``.

    The chain is top drive (``J_dt``), pipes (``J_pi``), collars (``J_co``), bit (``J_bi``)
    joined by ``k_pi``, ``k_co``, ``k_bi``; a clamped top or a stuck bit removes that inertia
    and grounds its spring.

    Args:
        params: Parameters or a preset name.
        top: ``"clamped"`` or ``"free"``.
        bit: ``"stuck"`` or ``"free"``.

    Raises:
        ValueError: naming ``top`` or ``bit`` when it is not one of the allowed values.
    """
    p = resolve_parameters(params)
    if top not in TOP_ENDS:
        raise ValueError(f"top = {shown(top)} is not valid: allowed {list(TOP_ENDS)}")
    if bit not in BIT_ENDS:
        raise ValueError(f"bit = {shown(bit)} is not valid: allowed {list(BIT_ENDS)}")
    names = ["top_drive", "pipes", "collars", "bit"]
    inertias = [p.J_dt, p.J_pi, p.J_co, p.J_bi]
    springs = [p.k_pi, p.k_co, p.k_bi]  # spring j joins inertia j and j + 1
    keep = [top == "free", True, True, bit == "free"]
    index = {j: n for n, j in enumerate(j for j in range(4) if keep[j])}
    size = len(index)
    stiffness = np.zeros((size, size))
    for j, k in enumerate(springs):
        for a in (j, j + 1):
            if a in index:
                stiffness[index[a], index[a]] += k
        if j in index and j + 1 in index:
            stiffness[index[j], index[j + 1]] -= k
            stiffness[index[j + 1], index[j]] -= k
    mass = np.diag([inertias[j] for j in index])
    # Symmetric form: M^-1/2 K M^-1/2 has the same eigenvalues and real, orthogonal vectors.
    scale = 1.0 / np.sqrt(np.diag(mass))
    w2, vectors = np.linalg.eigh(stiffness * scale[:, None] * scale[None, :])
    shapes = vectors * scale[:, None]
    elastic = w2 > 1e-9 * max(float(w2.max()), 1.0)  # drop the rigid-body mode of free-free
    w2, shapes = w2[elastic], shapes[:, elastic]
    peak = shapes[np.abs(shapes).argmax(axis=0), np.arange(shapes.shape[1])]
    shapes = shapes / peak  # largest amplitude +1
    return StringModes(
        top=top,
        bit=bit,
        dofs=tuple(names[j] for j in index),
        frequencies_rad_s=np.sqrt(w2),
        shapes=shapes,
    )


class StringView(NamedTuple):
    """What a top-drive controller takes from its model of the string, for either plant kind
    (:func:`string_view`).

    Attributes:
        J_dt: Inertia of the top drive, kg m^2.
        c_dt: Its damping to ground, N m s/rad.
        k_pi: Stiffness of the spring at the top of the (4-DOF) string, N m/rad.
        c_pi: Damping of that spring, N m s/rad.
        impedance: Characteristic impedance of the drill pipe, N m s/rad.
        stick_slip_rad_s: The string's stick-slip frequency, rad/s.
    """

    J_dt: float
    c_dt: float
    k_pi: float
    c_pi: float
    impedance: float
    stick_slip_rad_s: float


def string_view(model: DrillStringParameters | DistributedStringParameters) -> StringView:
    """The numbers a controller tunes from, for the 4-DOF model or a distributed string.

    4-DOF model: its own ``J_dt``, ``c_dt``, ``k_pi``, ``c_pi``, the pipe impedance
    ``sqrt(k_pi J_pi)`` and the lowest clamped-top, stuck-bit mode (:func:`stick_slip_frequency`).
    Distributed string: the top drive's own inertia and bearing damping, the top spring of its
    4-DOF equivalent (:func:`drill_env.modes.lumped_equivalent`), the drill pipe's wave
    impedance ``I_p sqrt(G rho)`` and the lowest mode with the top drive clamped and the bit
    free (:func:`drill_env.modes.stick_slip_frequency_rad_s`): along a long pipe with a stiff
    BHA that pendulum mode is the one a stick-slip cycle rings at, while the stuck-bit mode is
    pinned by the BHA several times higher.
    """
    if isinstance(model, DistributedStringParameters):
        lumped = lumped_equivalent(model)
        return StringView(
            J_dt=model.top_drive_inertia_kg_m2,
            c_dt=model.damping.top_drive_nm_s_rad,
            k_pi=lumped.k_pi,
            c_pi=lumped.c_pi,
            impedance=distributed_pipe_impedance(model),
            stick_slip_rad_s=stick_slip_frequency_rad_s(model, bit="free"),
        )
    return StringView(
        J_dt=model.J_dt,
        c_dt=model.c_dt,
        k_pi=model.k_pi,
        c_pi=model.c_pi,
        impedance=pipe_impedance(model),
        stick_slip_rad_s=stick_slip_frequency(model),
    )


def stick_slip_frequency(params: DrillStringParameters | str = "zribi2024") -> float:
    """The lowest natural frequency with the top drive clamped and the bit stuck, rad/s."""
    return string_modes(params, "clamped", "stuck").lowest_rad_s


def pipe_impedance(params: DrillStringParameters | str = "zribi2024") -> float:
    """Characteristic torsional impedance of the drill pipe ``Z = sqrt(k_pi J_pi)``, N m s/rad."""
    p = resolve_parameters(params)
    return math.sqrt(p.k_pi * p.J_pi)


def pipe_travel_time_s(params: DrillStringParameters | str = "zribi2024") -> float:
    """One-way torsional wave travel time along the pipe ``sqrt(J_pi / k_pi)``, s."""
    p = resolve_parameters(params)
    return math.sqrt(p.J_pi / p.k_pi)


@overload
def top_drive_impedance(
    omega_rad_s: float, kp: float, ki: float, inertia: float, damping: float = ...
) -> complex: ...
@overload
def top_drive_impedance(
    omega_rad_s: npt.NDArray[np.float64],
    kp: float,
    ki: float,
    inertia: float,
    damping: float = ...,
) -> npt.NDArray[np.complex128]: ...
def top_drive_impedance(
    omega_rad_s: float | npt.NDArray[np.float64],
    kp: float,
    ki: float,
    inertia: float,
    damping: float = 0.0,
) -> complex | npt.NDArray[np.complex128]:
    """Mechanical impedance a PI speed-controlled top drive presents to the string, N m s/rad.

    For a perturbation of the top-drive speed ``W e^{i w t}`` under a fixed set-point the drive
    resists with ``T = -(i w J + c + kp + ki / (i w)) W``, so
    ``Z_td(w) = kp + c + i (w J - ki / w)`` (Kyllingstad & Nessjoen 2009).
    """
    w = np.asarray(omega_rad_s, dtype=np.float64)
    z = np.asarray(kp + damping + 1j * (w * inertia - ki / w), dtype=np.complex128)
    return complex(z) if z.ndim == 0 else z


@overload
def reflection_coefficient(drive_impedance: complex, string_impedance: float) -> complex: ...
@overload
def reflection_coefficient(
    drive_impedance: npt.NDArray[np.complex128], string_impedance: float
) -> npt.NDArray[np.complex128]: ...
def reflection_coefficient(
    drive_impedance: complex | npt.NDArray[np.complex128], string_impedance: float
) -> complex | npt.NDArray[np.complex128]:
    """Torsional-wave reflection coefficient at the top, ``r = (Z - Z_td) / (Z + Z_td)``.

    ``|r| = 1``: the wave is reflected whole (a stiff drive, ``Z_td`` large); ``r = 0``: it is
    absorbed (impedance matched).
    """
    return (string_impedance - drive_impedance) / (string_impedance + drive_impedance)
