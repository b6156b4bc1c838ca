"""A field-length (distributed) torsional drill string built from its geometry.

The string is a list of uniform sections from the top drive down to the bit (drill pipe first,
then the bottom-hole assembly, BHA), each a hollow steel tube. It is discretised into a chain of
lumped inertias joined by torsional springs (the lumped-mass finite-element model of the wave
equation ``rho J phi_tt = (G J phi_x)_x``):

* every section of length ``L_s`` is cut into ``n_s = max(1, ceil(L_s / element_length_m))``
  equal elements (so no element is longer than ``element_length_m``);
* element ``e`` of length ``l`` in a section with polar moment ``J = pi (OD^4 - ID^4) / 32``
  (m^4) is a spring ``k_e = G J / l`` (N m/rad) and carries the inertia ``rho J l`` (kg m^2),
  half of it lumped at each of its two end nodes;
* the top node also carries the top-drive inertia, the bottom node the bit inertia; the
  top-drive torque acts on the top node, the Karnopp bit-rock torque (``drill_env.friction``)
  on the bottom node.

Damping (:class:`StringDamping`): viscous torque of the mud along the string, ``k_t rho J w``
per unit length (the form of Aarsnes & Shor 2018, eq. 3), lumped at the nodes like the inertia;
Kelvin-Voigt material damping in every element, ``c_e = tau k_e`` in parallel with its spring;
bearing damping of the top drive and viscous damping of the bit, both to ground.

The chain has ``n`` nodes and ``n - 1`` elements; its state (see :mod:`drill_env.chain`) is
``(w_0, phi_0 - phi_1, w_1, ..., phi_{n-2} - phi_{n-1}, w_{n-1})``. The 4-DOF plant of
:mod:`drill_env.parameters` is the ``n = 4`` chain (:func:`chain_from_parameters`).

All quantities are SI: m, kg, Pa, s, rad, N m. Parameters are frozen dataclasses, validated on
creation; variants are made with :func:`dataclasses.replace` or :func:`with_measured_depth`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env.limits import (
    MAX_ELEMENTS,
    MAX_MEASURED_DEPTH_M,
    MAX_SECTIONS,
    MIN_ELEMENT_LENGTH_M,
)
from drill_env.parameters import PRESETS, DrillStringParameters
from drill_env.validation import check_real, require, shown

__all__ = [
    "DISTRIBUTED_PRESETS",
    "Chain",
    "DistributedStringParameters",
    "StringDamping",
    "StringSection",
    "chain_from_parameters",
    "discretize",
    "polar_moment_m4",
    "resolve_distributed_parameters",
    "resolve_plant",
    "section_element_counts",
    "with_measured_depth",
]

FloatArray = npt.NDArray[np.float64]


def _real(name: str, value: Any) -> float:
    number = check_real(name, value, "a finite number")
    if not math.isfinite(number):
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed a finite number")
    return number


_require = require


def polar_moment_m4(outer_diameter_m: float, inner_diameter_m: float) -> float:
    """Polar second moment of area of a tube, ``J = pi (OD^4 - ID^4) / 32``, m^4."""
    return math.pi * (outer_diameter_m**4 - inner_diameter_m**4) / 32.0


@dataclass(frozen=True)
class StringSection:
    """One uniform tubular section of the string.

    Attributes:
        length_m: Length along the hole, m (> 0).
        outer_diameter_m: Outer diameter OD, m (> 0).
        inner_diameter_m: Inner diameter ID, m (0 <= ID < OD; 0 for a solid bar).
        shear_modulus_pa: Shear modulus G, Pa (> 0).
        density_kg_m3: Density rho, kg/m^3 (> 0).
    """

    length_m: float
    outer_diameter_m: float
    inner_diameter_m: float
    shear_modulus_pa: float
    density_kg_m3: float

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, _real(f.name, getattr(self, f.name)))
        for name in ("length_m", "outer_diameter_m", "shear_modulus_pa", "density_kg_m3"):
            _require(name, getattr(self, name), "> 0", getattr(self, name) > 0)
        _require(
            "length_m", self.length_m, f"(0, {MAX_MEASURED_DEPTH_M:g}] m",
            self.length_m <= MAX_MEASURED_DEPTH_M,
        )  # fmt: skip
        od, idia = self.outer_diameter_m, self.inner_diameter_m
        _require(
            "inner_diameter_m", idia, f"0 <= inner_diameter_m < outer_diameter_m = {od}",
            0.0 <= idia < od,
        )  # fmt: skip

    @property
    def polar_moment_m4(self) -> float:
        """Polar second moment of area ``J = pi (OD^4 - ID^4) / 32``, m^4."""
        return polar_moment_m4(self.outer_diameter_m, self.inner_diameter_m)

    @property
    def inertia_per_length_kg_m(self) -> float:
        """Rotational inertia per unit length ``rho J``, kg m^2 / m."""
        return self.density_kg_m3 * self.polar_moment_m4

    @property
    def torsional_rigidity_nm2(self) -> float:
        """Torsional rigidity ``G J``, N m^2 (torque per unit twist rate)."""
        return self.shear_modulus_pa * self.polar_moment_m4

    @property
    def wave_speed_m_s(self) -> float:
        """Torsional wave speed ``c = sqrt(G / rho)``, m/s."""
        return math.sqrt(self.shear_modulus_pa / self.density_kg_m3)

    @property
    def impedance_nm_s_rad(self) -> float:
        """Characteristic torsional impedance ``J sqrt(G rho)``, N m s/rad."""
        return self.polar_moment_m4 * math.sqrt(self.shear_modulus_pa * self.density_kg_m3)

    @property
    def inertia_kg_m2(self) -> float:
        """Rotational inertia of the whole section ``rho J L``, kg m^2."""
        return self.inertia_per_length_kg_m * self.length_m

    @property
    def stiffness_nm_rad(self) -> float:
        """Static torsional stiffness of the whole section ``G J / L``, N m/rad."""
        return self.torsional_rigidity_nm2 / self.length_m


@dataclass(frozen=True)
class StringDamping:
    """Damping of the distributed string (the defaults and their sources are in
    ``docs/distributed-string.md``).

    Attributes:
        mud_rate_per_s: Viscous mud damping rate ``k_t``, 1/s: the mud exerts the torque
            ``k_t rho J w`` per metre of string turning at ``w`` (Aarsnes & Shor 2018, eq. 3).
            The default 0.0833 1/s is the rate with which the Open Drilling Project model of
            their Well B matched that well's field data (its source sets ``kt = 50`` and applies
            it as ``2 kt dt`` per second, dt = 0.83 ms). With it the lowest modes of
            ``field_2500m`` have damping ratios of 3-4 %.
        material_time_constant_s: Kelvin-Voigt time constant ``tau`` of the pipe steel, s: every
            element has the damper ``tau k_e`` in parallel with its spring ``k_e``, a loss factor
            ``omega tau`` (1e-3 at 1 rad/s, the order of the material damping of steel). It
            mostly damps the highest modes of the chain, which the discretisation resolves
            poorly anyway.
        top_drive_nm_s_rad: Bearing (viscous) damping of the top drive to ground, N m s/rad;
            the default is ``c_dt`` of the 4-DOF plant (425).
        bit_nm_s_rad: Viscous damping of the bit to ground, N m s/rad. Default 0: the mud drag
            on the BHA is already in ``mud_rate_per_s`` (the 4-DOF plant's ``c_bit = 50`` lumps
            that drag; :func:`drill_env.modes.lumped_equivalent` gives 25 for ``field_2500m``).
    """

    mud_rate_per_s: float = 0.0833
    material_time_constant_s: float = 1e-3
    top_drive_nm_s_rad: float = 425.0
    bit_nm_s_rad: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = _real(f.name, getattr(self, f.name))
            _require(f.name, value, ">= 0", value >= 0.0)
            object.__setattr__(self, f.name, value)


@dataclass(frozen=True)
class DistributedStringParameters:
    """A field drill string: its sections, end inertias, bit-rock friction and damping.

    Attributes:
        sections: Uniform sections from the top drive down to the bit (drill pipe first, then
            the BHA); a list is stored as a tuple. The first section is the drill pipe, whose
            length :func:`with_measured_depth` changes.
        top_drive_inertia_kg_m2: Inertia of the top drive (and everything turning with it at
            surface), kg m^2 (> 0).
        bit_inertia_kg_m2: Inertia of the bit, kg m^2 (>= 0; the bottom node also carries half
            of the lowest element).
        bit_radius_m: Bit radius R, m (> 0).
        mu_a: Static (maximum) bit-rock friction coefficient (``T_a = mu_a WOB R``).
        mu_0: Sliding friction coefficient (``T_0 = mu_0 WOB R``), 0 < mu_0 <= mu_a.
        xi: Decline rate of the Stribeck term ``exp(-xi |w_bit|)``, s/rad (>= 0).
        Dw: Half-width of the Karnopp stick band, rad/s (> 0).
        damping: Damping of the string (:class:`StringDamping`).
        element_length_m: Longest element of the discretisation, m (> 0); see :func:`discretize`.
    """

    sections: tuple[StringSection, ...]
    top_drive_inertia_kg_m2: float
    bit_inertia_kg_m2: float
    bit_radius_m: float
    mu_a: float = 0.8
    mu_0: float = 0.5
    xi: float = 0.5
    Dw: float = 1e-3
    damping: StringDamping = field(default_factory=StringDamping)
    element_length_m: float = 25.0

    def __post_init__(self) -> None:
        sections = self.sections
        if isinstance(sections, (str, bytes)) or not hasattr(sections, "__iter__"):
            raise TypeError(
                f"sections must be a sequence of StringSection, got {type(sections).__name__}"
            )
        sections = tuple(sections)
        if not sections:
            raise ValueError("sections = () is out of range: allowed at least one StringSection")
        if len(sections) > MAX_SECTIONS:
            raise ValueError(
                f"sections has {len(sections)} entries: allowed at most {MAX_SECTIONS}"
            )
        for i, section in enumerate(sections):
            if not isinstance(section, StringSection):
                raise TypeError(
                    f"sections[{i}] must be a StringSection, got {type(section).__name__}"
                )
        object.__setattr__(self, "sections", sections)
        if not isinstance(self.damping, StringDamping):
            raise TypeError(f"damping must be a StringDamping, got {type(self.damping).__name__}")
        for name in (
            "top_drive_inertia_kg_m2", "bit_inertia_kg_m2", "bit_radius_m",
            "mu_a", "mu_0", "xi", "Dw", "element_length_m",
        ):  # fmt: skip
            object.__setattr__(self, name, _real(name, getattr(self, name)))
        for name in ("top_drive_inertia_kg_m2", "bit_radius_m", "Dw"):
            _require(name, getattr(self, name), "> 0", getattr(self, name) > 0)
        depth = self.measured_depth_m
        _require(
            "measured_depth_m (the sum of the section lengths)", depth,
            f"at most {MAX_MEASURED_DEPTH_M:g} m", depth <= MAX_MEASURED_DEPTH_M,
        )  # fmt: skip
        h = self.element_length_m
        _require("element_length_m", h, f">= {MIN_ELEMENT_LENGTH_M:g} m",
                 h >= MIN_ELEMENT_LENGTH_M)  # fmt: skip
        elements = sum(section_element_counts(self))
        _require(
            "element_length_m", h,
            f"a length that cuts this {depth:g} m string into at most {MAX_ELEMENTS} elements "
            f"(it gives {elements}; use >= {depth / (MAX_ELEMENTS - len(sections)):.3g} m)",
            elements <= MAX_ELEMENTS,
        )  # fmt: skip
        for name in ("bit_inertia_kg_m2", "xi"):
            _require(name, getattr(self, name), ">= 0", getattr(self, name) >= 0)
        _require("mu_0", self.mu_0, f"0 < mu_0 <= mu_a = {self.mu_a}", 0 < self.mu_0 <= self.mu_a)

    @property
    def measured_depth_m(self) -> float:
        """Total length of the string (bit depth along the hole), m."""
        return sum(s.length_m for s in self.sections)

    @property
    def pipe(self) -> StringSection:
        """The drill pipe: the first (top) section."""
        return self.sections[0]

    @property
    def bha_length_m(self) -> float:
        """Length of everything below the drill pipe (the BHA), m."""
        return sum(s.length_m for s in self.sections[1:])

    def static_torque_nm(self, wob_n: float) -> float:
        """Maximum static bit torque ``T_a = mu_a WOB R``, N m."""
        return self.mu_a * wob_n * self.bit_radius_m

    def sliding_torque_nm(self, wob_n: float) -> float:
        """Sliding bit torque ``T_0 = mu_0 WOB R``, N m."""
        return self.mu_0 * wob_n * self.bit_radius_m


def resolve_distributed_parameters(
    value: str | DistributedStringParameters, name: str = "parameters"
) -> DistributedStringParameters:
    """Return the preset named ``value`` (see ``DISTRIBUTED_PRESETS``) or ``value`` itself;
    errors name the keyword ``name``."""
    if isinstance(value, DistributedStringParameters):
        return value
    if isinstance(value, str):
        try:
            return DISTRIBUTED_PRESETS[value]
        except KeyError:
            raise ValueError(
                f"{name} = {shown(value)} is not a known distributed preset: "
                f"allowed {sorted(DISTRIBUTED_PRESETS)}"
            ) from None
    raise TypeError(
        f"{name} must be a distributed preset name or a DistributedStringParameters, "
        f"got {type(value).__name__}"
    )


def with_measured_depth(
    parameters: str | DistributedStringParameters, measured_depth_m: float
) -> DistributedStringParameters:
    """The same string at another measured depth: the drill pipe (first section) is made longer
    or shorter, the BHA (all other sections) is kept.

    Args:
        parameters: A distributed preset name or parameter set.
        measured_depth_m: New total length, m; it must exceed the BHA length.

    Raises:
        ValueError: naming ``measured_depth_m`` when it is not longer than the BHA.
    """
    p = resolve_distributed_parameters(parameters)
    bha = p.bha_length_m
    allowed = f"> BHA length {bha} m and <= {MAX_MEASURED_DEPTH_M:g} m"
    depth = check_real("measured_depth_m", measured_depth_m, allowed)
    _require("measured_depth_m", depth, allowed, bha < depth <= MAX_MEASURED_DEPTH_M)
    pipe = dataclasses.replace(p.sections[0], length_m=depth - bha)
    return dataclasses.replace(p, sections=(pipe, *p.sections[1:]))


@dataclass(frozen=True, eq=False)
class Chain:
    """The discretised string: a chain of ``n`` lumped inertias and ``n - 1`` elements.

    Node 0 is the top drive, node ``n - 1`` the bit; element ``e`` joins nodes ``e`` and
    ``e + 1``. Arrays are read-only float64.

    Attributes:
        node_inertia_kg_m2: Inertia of each node, kg m^2, shape (n,).
        node_damping_nm_s_rad: Viscous damping of each node to ground (mud, top-drive bearing,
            bit), N m s/rad, shape (n,).
        element_stiffness_nm_rad: Spring of each element, N m/rad, shape (n - 1,).
        element_damping_nm_s_rad: Damper in parallel with each spring, N m s/rad, shape (n - 1,).
        node_depth_m: Depth of each node along the hole, m, shape (n,) (0, 1, 2, 3 for a 4-DOF
            plant, which has no geometry).
        bit_radius_m: Bit radius R, m.
        mu_a: Static friction coefficient.
        mu_0: Sliding friction coefficient.
        xi: Stribeck decline rate, s/rad.
        Dw: Stick band half-width, rad/s.
    """

    node_inertia_kg_m2: FloatArray
    node_damping_nm_s_rad: FloatArray
    element_stiffness_nm_rad: FloatArray
    element_damping_nm_s_rad: FloatArray
    node_depth_m: FloatArray
    bit_radius_m: float
    mu_a: float
    mu_0: float
    xi: float
    Dw: float

    def __post_init__(self) -> None:
        n = len(self.node_inertia_kg_m2)
        _require("number of nodes", n, ">= 2", n >= 2)
        for name, size in (
            ("node_inertia_kg_m2", n), ("node_damping_nm_s_rad", n), ("node_depth_m", n),
            ("element_stiffness_nm_rad", n - 1), ("element_damping_nm_s_rad", n - 1),
        ):  # fmt: skip
            array = np.array(getattr(self, name), dtype=np.float64)
            if array.shape != (size,):
                raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
            if not np.all(np.isfinite(array)):
                raise ValueError(f"{name} must be finite")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        _require("min node_inertia_kg_m2", float(self.node_inertia_kg_m2.min()), "> 0",
                 bool(self.node_inertia_kg_m2.min() > 0))  # fmt: skip
        _require("min element_stiffness_nm_rad", float(self.element_stiffness_nm_rad.min()),
                 "> 0", bool(self.element_stiffness_nm_rad.min() > 0))  # fmt: skip
        for name in ("node_damping_nm_s_rad", "element_damping_nm_s_rad"):
            low = float(getattr(self, name).min())
            _require(f"min {name}", low, ">= 0", low >= 0)

    @property
    def n_nodes(self) -> int:
        """Number of nodes ``n`` (the state has ``2 n - 1`` entries)."""
        return int(self.node_inertia_kg_m2.shape[0])

    @property
    def state_size(self) -> int:
        """Length ``2 n - 1`` of the state vector."""
        return 2 * self.n_nodes - 1

    @property
    def ground_damping_nm_s_rad(self) -> float:
        """Sum of all damping to ground, N m s/rad (what a rigid rotation at speed V pays)."""
        return float(self.node_damping_nm_s_rad.sum())

    def static_torque_nm(self, wob_n: float) -> float:
        """Maximum static bit torque ``T_a = mu_a WOB R``, N m."""
        return self.mu_a * wob_n * self.bit_radius_m

    def sliding_torque_nm(self, wob_n: float) -> float:
        """Sliding bit torque ``T_0 = mu_0 WOB R``, N m."""
        return self.mu_0 * wob_n * self.bit_radius_m


def section_element_counts(parameters: DistributedStringParameters) -> tuple[int, ...]:
    """Number of elements of each section: ``max(1, ceil(L_s / element_length_m))``."""
    h = parameters.element_length_m
    # The tolerance keeps a section of exactly k element lengths at k elements despite rounding.
    return tuple(max(1, math.ceil(s.length_m / h * (1.0 - 1e-12))) for s in parameters.sections)


def discretize(parameters: str | DistributedStringParameters) -> Chain:
    """The lumped chain of a distributed string (rules in the module docstring).

    Args:
        parameters: A distributed preset name or parameter set.

    Returns:
        The :class:`Chain`, with ``n = 1 + sum of the section element counts`` nodes.
    """
    p = resolve_distributed_parameters(parameters)
    damping = p.damping
    counts = section_element_counts(p)
    n_elements = sum(counts)
    inertia = np.zeros(n_elements + 1)
    mud = np.zeros(n_elements + 1)
    stiffness = np.empty(n_elements)
    depth = np.zeros(n_elements + 1)
    e = 0
    top = 0.0
    for section, count in zip(p.sections, counts, strict=True):
        length = section.length_m / count
        element_inertia = section.inertia_per_length_kg_m * length
        for _ in range(count):
            stiffness[e] = section.torsional_rigidity_nm2 / length
            inertia[e] += 0.5 * element_inertia
            inertia[e + 1] += 0.5 * element_inertia
            mud[e] += 0.5 * damping.mud_rate_per_s * element_inertia
            mud[e + 1] += 0.5 * damping.mud_rate_per_s * element_inertia
            depth[e] = top
            top += length
            depth[e + 1] = top
            e += 1
    inertia[0] += p.top_drive_inertia_kg_m2
    inertia[-1] += p.bit_inertia_kg_m2
    mud[0] += damping.top_drive_nm_s_rad
    mud[-1] += damping.bit_nm_s_rad
    return Chain(
        node_inertia_kg_m2=inertia,
        node_damping_nm_s_rad=mud,
        element_stiffness_nm_rad=stiffness,
        element_damping_nm_s_rad=damping.material_time_constant_s * stiffness,
        node_depth_m=depth,
        bit_radius_m=p.bit_radius_m,
        mu_a=p.mu_a,
        mu_0=p.mu_0,
        xi=p.xi,
        Dw=p.Dw,
    )


def resolve_plant(
    value: str | DrillStringParameters | DistributedStringParameters | Chain,
) -> DrillStringParameters | DistributedStringParameters | Chain:
    """A plant of either kind from a preset name (distributed presets first, then the 4-DOF
    ones) or the parameter object itself."""
    if isinstance(value, (DrillStringParameters, DistributedStringParameters, Chain)):
        return value
    if isinstance(value, str):
        if value in DISTRIBUTED_PRESETS:
            return DISTRIBUTED_PRESETS[value]
        if value in PRESETS:
            return PRESETS[value]
        raise ValueError(
            f"parameters = {shown(value)} is not a known preset: allowed "
            f"{sorted(DISTRIBUTED_PRESETS) + sorted(PRESETS)}"
        )
    raise TypeError(
        "parameters must be a preset name, a DrillStringParameters, a "
        f"DistributedStringParameters or a Chain, got {type(value).__name__}"
    )


def chain_from_parameters(
    parameters: str | DrillStringParameters | DistributedStringParameters | Chain,
) -> Chain:
    """The chain of either plant kind: :func:`discretize` for a distributed string, the ``n = 4``
    chain (top drive, pipes, collars, bit; ``c_dt`` and ``c_bit`` to ground) for the 4-DOF plant.
    A :class:`Chain` is returned as it is; a name is resolved by :func:`resolve_plant`.
    """
    parameters = resolve_plant(parameters)
    if isinstance(parameters, DistributedStringParameters):
        return discretize(parameters)
    if isinstance(parameters, DrillStringParameters):
        q = parameters
        return Chain(
            node_inertia_kg_m2=np.array([q.J_dt, q.J_pi, q.J_co, q.J_bi]),
            node_damping_nm_s_rad=np.array([q.c_dt, 0.0, 0.0, q.c_bit]),
            element_stiffness_nm_rad=np.array([q.k_pi, q.k_co, q.k_bi]),
            element_damping_nm_s_rad=np.array([q.c_pi, q.c_co, q.c_bi]),
            node_depth_m=np.arange(4, dtype=np.float64),
            bit_radius_m=q.R,
            mu_a=q.mu_a,
            mu_0=q.mu_0,
            xi=q.xi,
            Dw=q.Dw,
        )
    return parameters


# ----------------------------------------------------------------------------------- presets
# Well B of Aarsnes & Shor (2018), as in the Open Drilling Project's published parameter file
# of their torsional model: drill pipe OD/ID 0.146529/0.123024 m, G = 61 GPa; four BHA sections,
# G = 67 GPa; rho = 7850 kg/m^3; measured top-drive inertia 2,900 kg m^2.
_WELL_B_BHA: Final = tuple(
    StringSection(length, od, idia, 67e9, 7850.0)
    for length, od, idia in (
        (48.70, 0.150473, 0.096207),
        (114.80, 0.187322, 0.098912),
        (56.70, 0.209550, 0.071438),
        (38.88, 0.247280, 0.123391),
    )
)
_WELL_B_PIPE_OD_M: Final = 0.146529
_WELL_B_PIPE_ID_M: Final = 0.123024
_BHA_LENGTH_M: Final = sum(s.length_m for s in _WELL_B_BHA)

# An 8.5 in bit (R = 0.108 m) of about 50 kg taken as a solid disc, J = m R^2 / 2 = 0.29 kg m^2
# (a reasoned value; it is small beside the ~26 kg m^2 of BHA that the bottom node carries).
_BIT_RADIUS_M: Final = 0.108
_BIT_INERTIA_KG_M2: Final = 0.5 * 50.0 * _BIT_RADIUS_M**2

# API 5DP drill pipe, 5 in OD, 19.50 lb/ft nominal weight: wall 0.362 in, so
# ID = 5.000 - 2 x 0.362 = 4.276 in = 0.1086104 m; OD = 0.127 m. Carbon steel G = 79.3 GPa.
_API_5IN_19_5_OD_M: Final = 5.000 * 0.0254
_API_5IN_19_5_ID_M: Final = 4.276 * 0.0254

DISTRIBUTED_PRESETS: Final[dict[str, DistributedStringParameters]] = {
    # Aarsnes & Shor (2018) Well B at 2,500 m measured depth.
    "field_2500m": DistributedStringParameters(
        sections=(
            StringSection(
                2500.0 - _BHA_LENGTH_M, _WELL_B_PIPE_OD_M, _WELL_B_PIPE_ID_M, 61e9, 7850.0
            ),
            *_WELL_B_BHA,
        ),
        top_drive_inertia_kg_m2=2900.0,
        bit_inertia_kg_m2=_BIT_INERTIA_KG_M2,
        bit_radius_m=_BIT_RADIUS_M,
    ),
    # A deep well: 5,000 m of API 5 in 19.5 lb/ft pipe above the Well B BHA and top drive.
    "deep_5000m": DistributedStringParameters(
        sections=(
            StringSection(
                5000.0 - _BHA_LENGTH_M, _API_5IN_19_5_OD_M, _API_5IN_19_5_ID_M, 79.3e9, 7850.0
            ),
            *_WELL_B_BHA,
        ),
        top_drive_inertia_kg_m2=2900.0,
        bit_inertia_kg_m2=_BIT_INERTIA_KG_M2,
        bit_radius_m=_BIT_RADIUS_M,
    ),
}
