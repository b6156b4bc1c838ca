"""Safe output paths: every name that becomes part of a written file's path goes through here.

Names come from the command line and from files (a model's ``name``, a controller, a preset, a
level of realism, a duration read from results); none of them is trusted. :func:`safe_file_name`
reduces a name to one harmless path component, and :func:`output_path` joins such components
under a command's output folder and refuses any path that would leave it (through a symbolic
link, say). The studies build every path they write with :func:`output_path`.
"""

from __future__ import annotations

import hashlib
import re
import unicodedata
from pathlib import Path
from typing import Final

from drill_env.validation import shown

__all__ = ["MAX_NAME_CHARS", "inside_output", "output_file", "output_path", "safe_file_name"]

MAX_NAME_CHARS: Final = 120
"""Longest file name :func:`safe_file_name` returns (file systems allow 255 bytes)."""

_KEEP: Final = re.compile(r"[^A-Za-z0-9._+=-]+")
_DOTS: Final = re.compile(r"\.{2,}")
_RESERVED: Final = frozenset(
    ["con", "prn", "aux", "nul", "conin$", "conout$"]
    + [f"{device}{i}" for device in ("com", "lpt") for i in range(10)]
)
"""Device names Windows reserves, with any extension (``CON``, ``nul.txt``, ``COM1``)."""


def _digest(name: str) -> str:
    return hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]


def safe_file_name(name: object, max_chars: int = MAX_NAME_CHARS) -> str:
    """``name`` as one safe path component (a file name or a part of one).

    Letters, digits and ``. _ + = -`` are kept (accented letters lose their accents), every
    other run of characters (separators ``/`` and ``\\``, spaces, control characters, escape
    sequences, and runs of dots) becomes ``_``; leading dots, dashes and underscores go (no hidden files, no
    ``..``, nothing that reads as an option). Reserved device names get a leading ``_``. When
    anything was changed, or the result is longer than ``max_chars``, 8 hexadecimal digits of
    the original's SHA-256 are appended, so different names never map to one file
    (``a/b`` -> ``a_b-<digest>``, while ``a_b`` stays ``a_b``). The result is never empty and
    never longer than ``max_chars``.
    """
    text = str(name)
    ascii_text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    clean = _KEEP.sub("_", _DOTS.sub("_", ascii_text)).lstrip("._-")
    if clean.split(".")[0].lower() in _RESERVED:
        clean = "_" + clean
    if clean == text and 0 < len(clean) <= max_chars:
        return clean
    tag = _digest(text)
    room = max(1, max_chars - len(tag) - 1)
    stem = clean[:room].rstrip("._-") or "unnamed"
    return f"{stem}-{tag}"


def output_path(out: Path | str, *parts: object, suffix: str = "") -> Path:
    """``out / part / ... / part`` with every part reduced by :func:`safe_file_name` and
    ``suffix`` (``".csv"``) appended to the last; the result is checked to lie inside ``out``
    once symbolic links are resolved.

    Raises:
        ValueError: naming the path when it would leave ``out`` (a link inside ``out`` that
            points elsewhere).
    """
    if not parts:
        raise ValueError("output_path needs at least one name under the output folder")
    if suffix and not re.fullmatch(r"\.[A-Za-z0-9]{1,8}", suffix):
        raise ValueError(f"suffix = {shown(suffix)} is not a file extension")
    base = Path(out)
    names = [safe_file_name(p) for p in parts]
    last = names[-1]
    room = MAX_NAME_CHARS - len(suffix)
    if len(last) > room:
        last = safe_file_name(parts[-1], room)
    names[-1] = last + suffix
    return inside_output(base, base.joinpath(*names))


def inside_output(out: Path | str, path: Path | str) -> Path:
    """``path`` as a ``Path`` after checking that it lies inside the output folder ``out``
    once symbolic links are resolved (a folder inside ``out`` that is a link to elsewhere, a
    ``..``); for a path built from ``out`` by a caller (a figure written into a subfolder).

    Raises:
        ValueError: one line naming the path, where it resolves and the output folder.
    """
    target = Path(path)
    try:
        root = Path(out).resolve()
        resolved = target.resolve()
    except (OSError, RuntimeError) as err:  # a loop of links (RuntimeError before 3.13)
        raise ValueError(
            f"refusing to write {str(target)!r}: its path cannot be resolved ({err}): remove "
            "the link or choose another output folder"
        ) from None
    if resolved != root and root not in resolved.parents:
        raise ValueError(
            f"refusing to write {str(target)!r}: it resolves to {str(resolved)!r}, outside the "
            f"output folder {str(root)!r} (a link inside it leads elsewhere: remove the link or "
            "choose another output folder)"
        )
    return target


def output_file(out: Path | str, *names: str) -> Path:
    """:func:`output_path` of a file name with its extension (``"speed_torque_csmc.png"``),
    the last of ``names``, in the subfolders the others name (``"figures"``): the stem is
    reduced by :func:`safe_file_name`, a short alphanumeric extension is kept; the whole path
    is checked against ``out``, so a subfolder that is a link to elsewhere is refused."""
    if not names:
        raise ValueError("output_file needs a file name under the output folder")
    *folders, file_name = names
    stem, dot, extension = str(file_name).rpartition(".")
    if dot and stem and re.fullmatch(r"[A-Za-z0-9]{1,8}", extension):
        return output_path(out, *folders, stem, suffix=f".{extension}")
    return output_path(out, *folders, file_name)
