"""Reading the arrays of the previous model format (format 2: ``.npz`` archives), without pickle.

Model folders of format 2 hold ``policy.npz`` and ``obs_norm.npz`` instead of the
safetensors files of today's format; an old Stable-Baselines3 ``model.zip`` came with an
``obs_norm.npz`` beside it. They are still read (``agents.load_policy``, ``drill-gym
convert``) by :func:`read_npz`: the zip directory is checked first (entry names, count,
declared uncompressed sizes, the ``.npy`` header of each entry: dtype float32 or float64, the
expected shape), then the arrays are read with ``np.load(allow_pickle=False)`` and checked to
be finite. NumPy and the standard library only.
"""

from __future__ import annotations

import io
import math
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Final

import numpy as np
import numpy.typing as npt

from drill_env.validation import shown

__all__ = ["LEGACY_NORM_FILE", "LEGACY_WEIGHTS_FILE", "PREVIOUS_FORMAT", "read_npz"]

PREVIOUS_FORMAT: Final = 2
"""The model format whose arrays are ``.npz`` archives."""
LEGACY_WEIGHTS_FILE: Final = "policy.npz"
LEGACY_NORM_FILE: Final = "obs_norm.npz"
MAX_NPY_HEADER: Final = 16_384
"""Bytes allowed per ``.npy`` entry on top of its float64 data (header and padding)."""
_FLOAT_DTYPES: Final = (np.dtype("<f4"), np.dtype("<f8"), np.dtype(">f4"), np.dtype(">f8"))


def _flat(text: str, limit: int = 200) -> str:
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


def read_npz(
    path: Path, expected: Mapping[str, tuple[int, ...]], what: str
) -> dict[str, npt.NDArray[np.float64]]:
    """Arrays of an ``.npz`` file, each float32 or float64 of the expected shape, all finite.

    The zip directory is checked before anything is decompressed: only ``NAME.npy`` entries
    for the expected names, at most their float64 size plus a header each (a zip bomb
    declares far more), stored or deflated, not encrypted; each entry's ``.npy`` header must
    declare a float dtype and the expected shape. Then ``np.load(allow_pickle=False)``.

    Args:
        path: The file.
        expected: Array name -> shape.
        what: What the file holds (for the messages).

    Returns:
        The arrays as float64, by name.

    Raises:
        FileNotFoundError: No such file.
        ValueError: One line naming the file and what is wrong.
    """
    where = str(path)
    if not path.is_file():
        raise FileNotFoundError(f"{where!r}: no such file (expected {what})")
    allowed = sum(8 * math.prod(s) + MAX_NPY_HEADER for s in expected.values())
    max_file = allowed + 1024 * (len(expected) + 1)
    with path.open("rb") as f:  # read once: the checks and np.load see the same bytes
        data = f.read(max_file + 1)
    if len(data) > max_file:
        size = max(path.stat().st_size, len(data))
        raise ValueError(
            f"{where!r}: {size} bytes is too large for {what}: allowed at most {max_file}"
        )
    bad = f"{where!r} is not valid {what} (an .npz archive of float arrays)"
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            _check_directory(archive, where, expected, what, allowed)
    except ValueError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, RuntimeError) as err:
        raise ValueError(f"{bad}: {_flat(str(err))}") from None
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            arrays = {k: np.asarray(archive[k]) for k in expected}
    except (ValueError, zipfile.BadZipFile, OSError, EOFError, KeyError) as err:
        raise ValueError(f"{bad}: {_flat(str(err))}") from None
    out: dict[str, npt.NDArray[np.float64]] = {}
    for name, array in arrays.items():
        if array.dtype not in _FLOAT_DTYPES or array.shape != tuple(expected[name]):
            raise ValueError(  # pragma: no cover - the headers were checked
                f"{where!r}: array {name} has dtype {array.dtype} and shape {array.shape}: "
                f"expected float32/float64 of shape {tuple(expected[name])}"
            )
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{where!r}: array {name} has non-finite values (NaN or inf)")
        out[name] = array.astype(np.float64)
    return out


def _check_directory(
    archive: zipfile.ZipFile,
    where: str,
    expected: Mapping[str, tuple[int, ...]],
    what: str,
    allowed: int,
) -> None:
    infos = archive.infolist()
    if len(infos) > len(expected):
        raise ValueError(
            f"{where!r}: {len(infos)} entries: expected {len(expected)} ({', '.join(expected)})"
        )
    declared = sum(i.file_size for i in infos)
    if declared > allowed:
        raise ValueError(
            f"{where!r}: its entries declare {declared} bytes uncompressed: allowed at most "
            f"{allowed} for {what} (a zip bomb?)"
        )
    names: list[str] = []
    for info in infos:
        name = info.filename[:-4] if info.filename.endswith(".npy") else ""
        if name not in expected or name in names:
            raise ValueError(
                f"{where!r}: unexpected entry {shown(info.filename)}: expected one each of "
                f"{', '.join(k + '.npy' for k in expected)}"
            )
        names.append(name)
        if info.flag_bits & 0x1 or info.compress_type not in (
            zipfile.ZIP_STORED,
            zipfile.ZIP_DEFLATED,
        ):
            raise ValueError(
                f"{where!r}: entry {shown(info.filename)} is encrypted or uses an unsupported "
                "compression: allowed stored or deflated"
            )
        with archive.open(info) as entry:
            _check_npy_header(entry, where, name, expected[name])
    missing = [k for k in expected if k not in names]
    if missing:
        raise ValueError(f"{where!r}: missing array(s) {', '.join(missing)} ({what})")


def _check_npy_header(entry: IO[bytes], where: str, name: str, shape: tuple[int, ...]) -> None:
    """The entry's ``.npy`` header declares a float dtype and ``shape`` (so that ``np.load``
    never allocates what the header claims before the data is read)."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(entry)
        if version == (1, 0):
            found, _, dtype = fmt.read_array_header_1_0(entry)
        elif version == (2, 0):
            found, _, dtype = fmt.read_array_header_2_0(entry)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except (ValueError, OSError, EOFError, SyntaxError, TypeError):
        raise ValueError(
            f"{where!r}: entry {name}.npy is not a valid .npy array: its header cannot be read "
            "(expected the .npy magic, a version and a dict of descr, fortran_order, shape)"
        ) from None
    if dtype not in _FLOAT_DTYPES:
        raise ValueError(
            f"{where!r}: array {name} has dtype {dtype}: allowed float32 or float64 "
            "(object and other dtypes are refused)"
        )
    if tuple(found) != tuple(shape):
        raise ValueError(f"{where!r}: array {name} has shape {tuple(found)}: expected {shape}")
