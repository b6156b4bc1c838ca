"""The ids the envs are registered under with Gymnasium (their one home; the package registers
them on import, :mod:`drill_env`)."""

from __future__ import annotations

from typing import Final

__all__ = ["COUPLED_ENV_ID", "ENV_ID", "FIELD_ENV_ID"]

ENV_ID: Final = "DrillString-v0"
"""The paper's 4-DOF lumped string (:class:`drill_env.env.DrillStringEnv`)."""
FIELD_ENV_ID: Final = "DrillStringField-v0"
"""The distributed field string (:class:`drill_env.env.DrillStringFieldEnv`)."""
COUPLED_ENV_ID: Final = "DrillStringCoupled-v0"
"""The coupled axial-torsional plant (:class:`drill_env.coupled_env.DrillStringCoupledEnv`)."""
