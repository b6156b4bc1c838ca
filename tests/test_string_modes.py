"""The industry baselines (stiff_pi, soft_speed, z_torque): the string's modal quantities, the
tuning formulas, hand-computed law outputs, gains validation, env integration, and the physics
they must show on a small stick-slip map."""

from __future__ import annotations

import math

import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from baselines.string_modes import (
    pipe_impedance,
    pipe_travel_time_s,
    stick_slip_frequency,
    string_modes,
)
from drill_env.parameters import PRESETS

INDUSTRY = ("stiff_pi", "soft_speed", "z_torque")
P = PRESETS["zribi2024"]
Z = math.sqrt(P.k_pi * P.J_pi)  # pipe impedance of the default plant, N m s/rad
DT = 1e-3


def quadratic_roots(a: float, b: float, c: float) -> tuple[float, float]:
    d = math.sqrt(b * b - 4 * a * c)
    return (-b - d) / (2 * a), (-b + d) / (2 * a)


# --------------------------------------------------------------------------- string modes
def test_clamped_stuck_modes_match_the_two_dof_closed_form() -> None:
    # Pipes and collars between a clamped top and a stuck bit:
    # det(K - w^2 M) = 0 with K = [[k_pi + k_co, -k_co], [-k_co, k_co + k_bi]].
    k11, k22, k12 = P.k_pi + P.k_co, P.k_co + P.k_bi, P.k_co
    w2 = quadratic_roots(P.J_pi * P.J_co, -(k11 * P.J_co + k22 * P.J_pi), k11 * k22 - k12 * k12)
    modes = string_modes(P, "clamped", "stuck")
    assert modes.dofs == ("pipes", "collars")
    np.testing.assert_allclose(modes.frequencies_rad_s, np.sqrt(w2), rtol=1e-12)
    assert stick_slip_frequency(P) == pytest.approx(math.sqrt(w2[0]), rel=1e-12)
    assert modes.periods_s[0] == pytest.approx(2 * math.pi / math.sqrt(w2[0]))


@pytest.mark.parametrize("top", ["clamped", "free"])
@pytest.mark.parametrize("bit", ["stuck", "free"])
def test_modes_solve_the_eigenproblem(top: str, bit: str) -> None:
    modes = string_modes("zribi2024", top, bit)  # type: ignore[arg-type]
    inertias = {"top_drive": P.J_dt, "pipes": P.J_pi, "collars": P.J_co, "bit": P.J_bi}
    names = ["top_drive", "pipes", "collars", "bit"]
    springs = [P.k_pi, P.k_co, P.k_bi]
    idx = {name: n for n, name in enumerate(modes.dofs)}
    k = np.zeros((len(idx), len(idx)))
    for j, kj in enumerate(springs):
        a, b = names[j], names[j + 1]
        for end in (a, b):
            if end in idx:
                k[idx[end], idx[end]] += kj
        if a in idx and b in idx:
            k[idx[a], idx[b]] -= kj
            k[idx[b], idx[a]] -= kj
    m = np.diag([inertias[name] for name in modes.dofs])
    for w, v in zip(modes.frequencies_rad_s, modes.shapes.T, strict=True):
        np.testing.assert_allclose(k @ v, w**2 * m @ v, atol=1e-9 * np.abs(k @ v).max())
    assert np.all(np.diff(modes.frequencies_rad_s) > 0)
    # A free-free string has one rigid-body mode, which is left out.
    assert len(modes.frequencies_rad_s) == len(modes.dofs) - (top == "free" and bit == "free")


def test_pipe_impedance_and_travel_time() -> None:
    assert pipe_impedance(P) == pytest.approx(Z)
    assert pipe_impedance(P) == pytest.approx(1393.62, abs=0.01)
    assert pipe_travel_time_s(P) == pytest.approx(math.sqrt(P.J_pi / P.k_pi))


def test_string_modes_rejects_bad_end_names() -> None:
    with pytest.raises(ValueError, match=r"top = 'pinned' is not valid"):
        string_modes(P, "pinned", "stuck")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"bit = 'loose' is not valid"):
        string_modes(P, "clamped", "loose")  # type: ignore[arg-type]
