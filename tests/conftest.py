"""Shared pytest configuration.

Helper modules in this folder (such as ``reference_solver``) are imported by their plain name.
pytest's default ``prepend`` import mode already puts this folder on ``sys.path`` (it has no
``__init__.py``); the lines below keep that true under ``--import-mode=importlib`` as well.
"""

import sys
from pathlib import Path

_TESTS_DIR = str(Path(__file__).resolve().parent)
if _TESTS_DIR not in sys.path:
    sys.path.insert(0, _TESTS_DIR)
