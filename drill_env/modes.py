"""Natural frequencies, linearisation and the 4-DOF equivalent of a torsional string.

Every function takes either plant kind: a :class:`drill_env.distributed.DistributedStringParameters`
(discretised by :func:`drill_env.distributed.discretize`), a 4-DOF
:class:`drill_env.parameters.DrillStringParameters` (the ``n = 4`` chain), a
:class:`drill_env.distributed.Chain`, or a preset name. Plain numpy (dense eigenproblems of the
chain; a few milliseconds for the presets), never inside the compiled loop.

End conditions of the modal problems: the top drive is ``"free"`` (its inertia turns freely) or
``"clamped"`` (its speed held, as a stiff speed loop does); the bit is ``"free"`` (off bottom, or
slipping) or ``"stuck"`` (held by static friction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from drill_env.chain import PlantLike, steady_drilling_state
from drill_env.distributed import (
    Chain,
    DistributedStringParameters,
    StringSection,
    chain_from_parameters,
    discretize,
    resolve_plant,
)
from drill_env.parameters import DrillStringParameters
from drill_env.validation import shown

__all__ = [
    "BIT_ENDS",
    "TOP_ENDS",
    "Linearization",
    "check_step_bound",
    "damped_modes",
    "highest_frequency_rad_s",
    "linearize",
    "lumped_equivalent",
    "probe_nodes",
    "natural_frequencies_hz",
    "pipe_impedance",
    "pipe_travel_time_s",
    "stick_slip_frequency_rad_s",
]

FloatArray = npt.NDArray[np.float64]
TopEnd = Literal["free", "clamped"]
BitEnd = Literal["free", "stuck"]
TOP_ENDS: Final = ("free", "clamped")
BIT_ENDS: Final = ("free", "stuck")


def _ends(top: str, bit: str) -> None:
    if top not in TOP_ENDS:
        raise ValueError(f"top = {shown(top)} is not valid: allowed {list(TOP_ENDS)}")
    if bit not in BIT_ENDS:
        raise ValueError(f"bit = {shown(bit)} is not valid: allowed {list(BIT_ENDS)}")


def _kept_nodes(chain: Chain, top: str, bit: str) -> npt.NDArray[np.int64]:
    n = chain.n_nodes
    first = 1 if top == "clamped" else 0
    last = n - 1 if bit == "stuck" else n
    return np.arange(first, last)


def _matrices(chain: Chain) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Diagonal of M, and the full C and K of the chain in absolute node angles."""
    n = chain.n_nodes
    k = np.zeros((n, n))
    c = np.diag(chain.node_damping_nm_s_rad.astype(np.float64))
    for e in range(n - 1):
        ke = chain.element_stiffness_nm_rad[e]
        ce = chain.element_damping_nm_s_rad[e]
        k[e : e + 2, e : e + 2] += ke * np.array([[1.0, -1.0], [-1.0, 1.0]])
        c[e : e + 2, e : e + 2] += ce * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return chain.node_inertia_kg_m2.astype(np.float64), c, k


def _count(count: int, available: int) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)):
        raise TypeError(f"count must be an integer, got {shown(count)}")
    if not 1 <= count <= available:
        raise ValueError(f"count = {shown(count)} is out of range: allowed 1..{available}")
    return int(count)


def natural_frequencies_hz(
    parameters: PlantLike, count: int = 3, *, top: TopEnd = "free", bit: BitEnd = "free"
) -> FloatArray:
    """Lowest undamped torsional natural frequencies, Hz, ascending.

    Solves ``K v = (2 pi f)^2 M v`` of the chain. With both ends free the rigid-body mode (a
    rotation of the whole string, f = 0) is left out, so the first value is the lowest
    non-zero frequency.

    Args:
        parameters: Plant of either kind (see the module docstring).
        count: How many frequencies to return (>= 1).
        top: ``"free"`` (default) or ``"clamped"``.
        bit: ``"free"`` (default, bit off bottom) or ``"stuck"``.

    Returns:
        Shape ``(count,)``.
    """
    _ends(top, bit)
    chain = chain_from_parameters(resolve_plant(parameters))
    m, _, k = _matrices(chain)
    keep = _kept_nodes(chain, top, bit)
    scale = 1.0 / np.sqrt(m[keep])
    sym = k[np.ix_(keep, keep)] * scale[:, None] * scale[None, :]
    w2 = np.linalg.eigvalsh(sym)
    rigid = 1 if (top == "free" and bit == "free") else 0
    w2 = w2[rigid:]
    n = _count(count, w2.size)
    return np.sqrt(np.maximum(w2[:n], 0.0)) / (2.0 * np.pi)


def _stiffness_tridiagonal(chain: Chain) -> tuple[list[float], list[float]]:
    """The mass-normalised stiffness ``M^-1/2 K M^-1/2`` of the chain (both ends free), a
    symmetric tridiagonal matrix: its diagonal and the squares of its off-diagonal, 1/s^2."""
    m = chain.node_inertia_kg_m2
    k = chain.element_stiffness_nm_rad
    left = np.concatenate(([0.0], k))
    right = np.concatenate((k, [0.0]))
    diagonal = (left + right) / m
    off_squared = k * k / (m[:-1] * m[1:])
    return diagonal.tolist(), off_squared.tolist()


def _eigenvalues_below(diagonal: list[float], off_squared: list[float], x: float) -> int:
    """How many eigenvalues of the symmetric tridiagonal matrix are below ``x`` (the Sturm
    count of its ``L D L^T`` factorisation; linear in the size, no matrix is formed)."""
    tiny = 1e-300
    count = 0
    q = diagonal[0] - x
    for i in range(len(diagonal)):
        if i:
            q = diagonal[i] - x - off_squared[i - 1] / q
        if q == 0.0:
            q = -tiny
        if q < 0.0:
            count += 1
    return count


def highest_frequency_rad_s(parameters: PlantLike) -> float:
    """Highest undamped natural frequency of the chain (both ends free), rad/s.

    About ``2 c / l`` for elements of length ``l`` and wave speed ``c``. Classical RK4 is stable
    for ``h omega <= 2.8`` on the imaginary axis; keep ``h * highest_frequency_rad_s <= 2`` (at
    h = 1 ms it is 0.30 for ``field_2500m``, set by its 18.9 m BHA elements). Found by bisection
    on the Sturm count of the tridiagonal stiffness (relative accuracy 1e-14, linear in the
    size of the chain).
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    diagonal, off_squared = _stiffness_tridiagonal(chain)
    n = len(diagonal)
    off = [math.sqrt(v) for v in off_squared]
    # Gershgorin's discs hold every eigenvalue: [low, high] brackets the highest one.
    high = max(
        d + (off[i - 1] if i else 0.0) + (off[i] if i < n - 1 else 0.0)
        for i, d in enumerate(diagonal)
    )
    low = max(diagonal)  # the Rayleigh quotient of a unit vector: a lower bound
    while high - low > 1e-14 * high:
        middle = 0.5 * (low + high)
        if middle in (low, high):
            break
        if _eigenvalues_below(diagonal, off_squared, middle) == n:
            high = middle
        else:
            low = middle
    return math.sqrt(max(0.5 * (low + high), 0.0))


MAX_STEP_FREQUENCY: Final = 2.0
"""Largest ``h * highest_frequency_rad_s`` accepted for the plant step ``h`` (RK4 is stable up
to about 2.8 on the imaginary axis)."""


def check_step_bound(parameters: PlantLike, step_s: float) -> None:
    """Raise ``ValueError`` when the plant step is too long for the chain's highest mode.

    A cheap upper bound (Gershgorin's discs of the mass-normalised stiffness) decides most
    strings; otherwise one Sturm count of the tridiagonal stiffness tells whether any mode is
    above the limit (linear in the size: a refusal takes milliseconds at any size).
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    inertia, k = chain.node_inertia_kg_m2, chain.element_stiffness_nm_rad
    left = np.concatenate(([0.0], k))
    right = np.concatenate((k, [0.0]))
    scale = 1.0 / np.sqrt(inertia)
    coupling = np.zeros_like(inertia)
    coupling[1:] += k * scale[1:] * scale[:-1]
    coupling[:-1] += k * scale[1:] * scale[:-1]
    bound = math.sqrt(float(np.max((left + right) / inertia + coupling)))
    if bound * step_s <= MAX_STEP_FREQUENCY:
        return
    diagonal, off_squared = _stiffness_tridiagonal(chain)
    limit = (MAX_STEP_FREQUENCY / step_s) ** 2
    if _eigenvalues_below(diagonal, off_squared, limit) < len(diagonal):
        highest = highest_frequency_rad_s(chain)
        shortest = float(np.min(chain.node_depth_m[1:] - chain.node_depth_m[:-1]))
        plant = resolve_plant(parameters)
        length = getattr(plant, "element_length_m", shortest)
        raise ValueError(
            f"element_length_m = {shown(length)} is out of range for the plant step of {step_s} s: "
            f"its shortest element ({shortest:.3g} m) makes the highest mode {highest:.4g} "
            f"rad/s, allowed h * omega <= {MAX_STEP_FREQUENCY} (use longer elements)"
        )


def damped_modes(
    parameters: PlantLike, count: int = 3, *, top: TopEnd = "free", bit: BitEnd = "free"
) -> tuple[FloatArray, FloatArray]:
    """Natural frequencies and damping ratios of the damped linear chain (no bit friction).

    Eigenvalues ``lambda`` of ``M q'' + C q' + K q = 0`` come in pairs ``-zeta w +- i w
    sqrt(1 - zeta^2)``; the underdamped pairs are sorted by ``w = |lambda|`` and returned as
    ``(w / 2 pi, zeta)``. Real eigenvalues (the rigid-body rotation, overdamped modes) are left
    out.

    Returns:
        ``(frequencies_hz, damping_ratios)``, each shape ``(count,)``.
    """
    _ends(top, bit)
    chain = chain_from_parameters(resolve_plant(parameters))
    m, c, k = _matrices(chain)
    keep = _kept_nodes(chain, top, bit)
    size = keep.size
    inv_m = 1.0 / m[keep]
    a = np.zeros((2 * size, 2 * size))
    a[:size, size:] = np.eye(size)
    a[size:, :size] = -k[np.ix_(keep, keep)] * inv_m[:, None]
    a[size:, size:] = -c[np.ix_(keep, keep)] * inv_m[:, None]
    lam = np.linalg.eigvals(a)
    lam = lam[lam.imag > 1e-9 * max(1.0, float(np.abs(lam).max()))]
    lam = lam[np.argsort(np.abs(lam))]
    n = _count(count, lam.size)
    w = np.abs(lam[:n])
    return w / (2.0 * np.pi), -lam[:n].real / w


def stick_slip_frequency_rad_s(parameters: PlantLike, *, bit: BitEnd = "free") -> float:
    """Lowest natural frequency with the top drive clamped, rad/s (the stick-slip frequency).

    A stiff speed-controlled top drive holds the top still for perturbations, so a stick-slip
    cycle rings at the lowest clamped-top mode. With ``bit="free"`` (default) the BHA and bit
    swing freely below the pipe, as in the slip phase; for a uniform pipe this is the
    quarter-wave mode ``pi c / (2 L)`` (Kyllingstad & Halsey 1988). ``bit="stuck"`` holds the
    bottom node: for a field BHA, tens of times stiffer than the pipe, that pins the pipe's
    lower end and gives nearly the pipe's half-wave mode ``pi c / L`` instead.
    """
    return float(2.0 * np.pi * natural_frequencies_hz(parameters, 1, top="clamped", bit=bit)[0])


def _pipe(parameters: PlantLike) -> StringSection | DrillStringParameters:
    plant = resolve_plant(parameters)
    if isinstance(plant, DistributedStringParameters):
        return plant.pipe
    if isinstance(plant, DrillStringParameters):
        return plant
    raise TypeError(
        "parameters must be a DistributedStringParameters or a DrillStringParameters "
        f"(a bare Chain has no pipe geometry), got {type(plant).__name__}"
    )


def pipe_impedance(parameters: PlantLike) -> float:
    """Characteristic torsional impedance of the drill pipe, N m s/rad.

    ``J sqrt(G rho)`` of the first (pipe) section of a distributed string (Kyllingstad &
    Halsey 1988; Dwars 2015); ``sqrt(k_pi J_pi)`` for the 4-DOF plant, which is the same
    quantity for a uniform pipe of stiffness ``k = G J / L`` and inertia ``rho J L``.
    """
    pipe = _pipe(parameters)
    if isinstance(pipe, StringSection):
        return pipe.impedance_nm_s_rad
    return math.sqrt(pipe.k_pi * pipe.J_pi)


def pipe_travel_time_s(parameters: PlantLike) -> float:
    """One-way travel time of a torsional wave along the drill pipe, s: ``L / c``
    (``sqrt(J_pi / k_pi)`` for the 4-DOF plant)."""
    pipe = _pipe(parameters)
    if isinstance(pipe, StringSection):
        return pipe.length_m / pipe.wave_speed_m_s
    return math.sqrt(pipe.J_pi / pipe.k_pi)


# ------------------------------------------------------------------------------ linearisation
@dataclass(frozen=True, eq=False)
class Linearization:
    """Linear model ``dx' = A dx + B du``, ``dy = C dx + D du`` about steady drilling.

    ``dx = x - x_eq`` etc. Use with python-control as ``control.ss(lin.A, lin.B, lin.C, lin.D)``
    (python-control is not a dependency of this package).

    Attributes:
        A: State matrix, shape (2 n - 1, 2 n - 1), 1/s.
        B: Input matrix, shape (2 n - 1, 2).
        C: Output matrix, shape (3, 2 n - 1).
        D: Feed-through, shape (3, 2) (zero).
        state_names: ``("w0_rad_s", "twist0_rad", "w1_rad_s", ..., "w{n-1}_rad_s")``: node 0 is
            the top drive, node n - 1 the bit.
        input_names: ``("top_drive_torque_nm", "wob_n")``.
        output_names: ``("top_drive_speed_rad_s", "bit_speed_rad_s", "top_torque_nm")``; the
            last is the torque in the top element of the string (what a torque sub under the
            top drive measures), ``k_0 theta_0 + c_0 (w_0 - w_1)``.
        x_eq: State of steady drilling, shape (2 n - 1,).
        u_eq: ``(top-drive torque N m, WOB N)`` of steady drilling, shape (2,).
        bit_speed_rad_s: Bit speed of the operating point, rad/s.
        friction_slope_nm_s_rad: ``d T_bit / d w_bit`` at the operating point, N m s/rad
            (negative: velocity weakening, which enters A as negative damping at the bit).
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    D: FloatArray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    x_eq: FloatArray
    u_eq: FloatArray
    bit_speed_rad_s: float
    friction_slope_nm_s_rad: float

    def __post_init__(self) -> None:
        for name in ("A", "B", "C", "D", "x_eq", "u_eq"):
            array = np.array(getattr(self, name), dtype=np.float64)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def eigenvalues(self) -> npt.NDArray[np.complex128]:
        """Eigenvalues of ``A``, 1/s (a positive real part is an unstable, growing mode)."""
        return np.asarray(np.linalg.eigvals(self.A), dtype=np.complex128)


def linearize(parameters: PlantLike, wob_n: float, bit_speed_rad_s: float) -> Linearization:
    """Linearise the chain about steady drilling at ``bit_speed_rad_s > 0`` (bit slipping
    forwards), the bit friction's slope ``d T_bit / d w`` included.

    Args:
        parameters: Plant of either kind (see the module docstring).
        wob_n: Weight on bit, N (> 0).
        bit_speed_rad_s: Speed of every node at the operating point, rad/s (> 0).
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    x_eq, u_eq = steady_drilling_state(chain, wob_n, bit_speed_rad_s)
    n = chain.n_nodes
    size = 2 * n - 1
    v = float(bit_speed_rad_s)
    t_a, t_0 = chain.static_torque_nm(wob_n), chain.sliding_torque_nm(wob_n)
    decay = math.exp(-chain.xi * v)
    slope = -(t_a - t_0) * chain.xi * decay  # d T_bit / d w at w = v > 0
    d_t_d_wob = chain.bit_radius_m * (chain.mu_0 + (chain.mu_a - chain.mu_0) * decay)
    inv_j = 1.0 / chain.node_inertia_kg_m2
    d = chain.node_damping_nm_s_rad
    k = chain.element_stiffness_nm_rad
    c = chain.element_damping_nm_s_rad
    a = np.zeros((size, size))
    for e in range(n - 1):
        w_up, twist, w_down = 2 * e, 2 * e + 1, 2 * e + 2
        a[twist, w_up] = 1.0
        a[twist, w_down] = -1.0
        # tau_e = k theta + c (w_up - w_down) leaves node e and enters node e + 1
        for row, sign in ((w_up, -1.0), (w_down, 1.0)):
            node = row // 2
            a[row, twist] += sign * k[e] * inv_j[node]
            a[row, w_up] += sign * c[e] * inv_j[node]
            a[row, w_down] -= sign * c[e] * inv_j[node]
    for i in range(n):
        a[2 * i, 2 * i] -= d[i] * inv_j[i]
    a[size - 1, size - 1] -= slope * inv_j[n - 1]
    b = np.zeros((size, 2))
    b[0, 0] = inv_j[0]
    b[size - 1, 1] = -d_t_d_wob * inv_j[n - 1]
    out = np.zeros((3, size))
    out[0, 0] = 1.0
    out[1, size - 1] = 1.0
    out[2, 1] = k[0]
    out[2, 0] = c[0]
    out[2, 2] = -c[0]
    names: list[str] = []
    for i in range(n):
        names.append(f"w{i}_rad_s")
        if i < n - 1:
            names.append(f"twist{i}_rad")
    return Linearization(
        A=a,
        B=b,
        C=out,
        D=np.zeros((3, 2)),
        state_names=tuple(names),
        input_names=("top_drive_torque_nm", "wob_n"),
        output_names=("top_drive_speed_rad_s", "bit_speed_rad_s", "top_torque_nm"),
        x_eq=x_eq,
        u_eq=np.array([u_eq, float(wob_n)]),
        bit_speed_rad_s=v,
        friction_slope_nm_s_rad=slope,
    )


# ------------------------------------------------------------------------ 4-DOF equivalent
def _split_bha(sections: tuple[StringSection, ...]) -> tuple[float, float, float, float]:
    """(inertia kg m^2, compliance rad/(N m)) of the upper and lower halves (by length) of the
    BHA sections."""
    total = sum(s.length_m for s in sections)
    half = 0.5 * total
    inertia = [0.0, 0.0]
    compliance = [0.0, 0.0]
    top = 0.0
    for s in sections:
        bottom = top + s.length_m
        upper = max(0.0, min(bottom, half) - top)  # length of this section above the midpoint
        for part, length in ((0, upper), (1, s.length_m - upper)):
            inertia[part] += s.inertia_per_length_kg_m * length
            compliance[part] += length / s.torsional_rigidity_nm2
        top = bottom
    return inertia[0], compliance[0], inertia[1], compliance[1]


def _four_dof(p: DistributedStringParameters, alpha: float) -> DrillStringParameters:
    pipe = p.pipe
    j_pipe = pipe.inertia_kg_m2
    j_up, s_up, j_low, s_low = _split_bha(p.sections[1:])
    tau = p.damping.material_time_constant_s
    k_pi = pipe.stiffness_nm_rad
    k_co, k_bi = 1.0 / s_up, 1.0 / s_low
    mud = p.damping.mud_rate_per_s
    return DrillStringParameters(
        J_dt=p.top_drive_inertia_kg_m2 + (1.0 - alpha) * j_pipe,
        J_pi=alpha * j_pipe + 0.5 * j_up,
        J_co=0.5 * (j_up + j_low),
        J_bi=p.bit_inertia_kg_m2 + 0.5 * j_low,
        c_dt=p.damping.top_drive_nm_s_rad + mud * j_pipe,
        c_pi=tau * k_pi,
        c_co=tau * k_co,
        c_bi=tau * k_bi,
        c_bit=p.damping.bit_nm_s_rad + mud * (j_up + j_low),
        k_pi=k_pi,
        k_co=k_co,
        k_bi=k_bi,
        R=p.bit_radius_m,
        mu_a=p.mu_a,
        mu_0=p.mu_0,
        xi=p.xi,
        Dw=p.Dw,
    )


def probe_nodes(parameters: str | DistributedStringParameters) -> tuple[int, int, int, int]:
    """The chain nodes that stand for the 4-DOF plant's top drive, pipes, collars and bit: node
    0, the pipe/BHA junction, the node nearest the middle of the BHA (by length) and the bit;
    the nodes of :func:`lumped_equivalent`'s rule, used to read a distributed string's state
    in the 4-DOF coordinates (:func:`drill_env.chain.chain_probe_state`)."""
    p = resolve_plant(parameters)
    if not isinstance(p, DistributedStringParameters):
        raise TypeError(f"parameters must be a DistributedStringParameters, got {type(p).__name__}")
    if len(p.sections) < 2:
        raise ValueError(
            f"sections has {len(p.sections)} section: allowed at least 2 (pipe and BHA)"
        )
    depth = discretize(p).node_depth_m
    junction = int(np.argmin(np.abs(depth - p.pipe.length_m)))
    middle = int(np.argmin(np.abs(depth - (p.pipe.length_m + 0.5 * p.bha_length_m))))
    last = depth.shape[0] - 1
    middle = min(max(middle, junction + 1), last - 1)
    return (0, junction, middle, last)


def lumped_equivalent(parameters: str | DistributedStringParameters) -> DrillStringParameters:
    """The 4-DOF plant (top drive, pipes, collars, bit) that stands for a distributed string.

    Rule (nodes: top drive; the pipe/BHA junction; the middle of the BHA; the bit):

    * stiffness: ``k_pi`` is the static stiffness ``G J / L`` of the drill pipe, ``k_co`` and
      ``k_bi`` those of the upper and lower halves (by length) of the BHA, so the static
      compliance of the whole string is kept;
    * inertia: each BHA half gives half its inertia to each of its end nodes, the top drive
      and the bit keep their own; the pipe's inertia ``J_p`` is split, ``(1 - alpha) J_p`` to
      the top drive and ``alpha J_p`` to the pipe node, with ``alpha`` chosen so that the
      4-DOF stick-slip frequency (top clamped, bit free) equals the distributed string's. The
      total inertia is kept;
    * damping: Kelvin-Voigt in every spring (``c = tau k``, exact for springs in series); the
      mud damping of the pipe goes to the top drive (``c_dt``) and that of the BHA to the bit
      (``c_bit``), so the total damping to ground, hence the steady drilling torque, is kept;
    * friction: bit radius and Karnopp law copied.

    Raises:
        ValueError: when the string has no BHA (a single section).
    """
    p = resolve_plant(parameters)
    if not isinstance(p, DistributedStringParameters):
        raise TypeError(f"parameters must be a DistributedStringParameters, got {type(p).__name__}")
    if len(p.sections) < 2:
        raise ValueError(
            f"sections has {len(p.sections)} section: allowed at least 2 (pipe and BHA)"
        )
    target = stick_slip_frequency_rad_s(discretize(p))
    lo, hi = 0.0, 1.0
    f_lo = stick_slip_frequency_rad_s(_four_dof(p, lo)) - target
    f_hi = stick_slip_frequency_rad_s(_four_dof(p, hi)) - target
    if f_lo * f_hi > 0.0:
        # Outside the bracket: keep the end that comes closest.
        return _four_dof(p, lo if abs(f_lo) < abs(f_hi) else hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = stick_slip_frequency_rad_s(_four_dof(p, mid)) - target
        if f_mid * f_lo > 0.0:
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return _four_dof(p, 0.5 * (lo + hi))
