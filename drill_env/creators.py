"""The functions Gymnasium's registry calls to make each env (its ``entry_point``).

``gymnasium.make`` compares ``render_mode`` with the ``metadata`` of the class it is given
*before* calling it: an unknown value is printed in a warning with ``repr``, unbounded (a
10 MB string, or an object whose ``repr`` is hostile), and a value that is not a string fails
inside Gymnasium (``AttributeError: ... 'endswith'``) before any check of ours. These functions
have no ``metadata``, so Gymnasium passes ``render_mode`` on untouched and the env's constructor
refuses a bad one first, with the one-line bounded message of
:func:`drill_env.render.check_render_mode`. Each returns the env class's instance itself (no
wrapper), made with exactly the keywords given. Gymnasium imports this module only when it
makes an env, so ``import drill_env`` stays light.
"""

from __future__ import annotations

from typing import Any

from drill_env.coupled_env import DrillStringCoupledEnv
from drill_env.env import DrillStringEnv, DrillStringFieldEnv

__all__ = ["make_coupled_env", "make_drill_string_env", "make_field_env"]


def make_drill_string_env(**kwargs: Any) -> DrillStringEnv:
    """``DrillString-v0``: :class:`drill_env.env.DrillStringEnv` ``(**kwargs)``."""
    return DrillStringEnv(**kwargs)


def make_field_env(**kwargs: Any) -> DrillStringFieldEnv:
    """``DrillStringField-v0``: :class:`drill_env.env.DrillStringFieldEnv` ``(**kwargs)``."""
    return DrillStringFieldEnv(**kwargs)


def make_coupled_env(**kwargs: Any) -> DrillStringCoupledEnv:
    """``DrillStringCoupled-v0``: :class:`drill_env.coupled_env.DrillStringCoupledEnv`
    ``(**kwargs)``."""
    return DrillStringCoupledEnv(**kwargs)
