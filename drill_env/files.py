"""Writing a file whole or not at all, and never through a link: the one file writer.

Every file the package and its commands write (tables, figures, reports, ``plant.json``, the
tuned gains file, model files) goes through :func:`replacing`: the content is written to a new
temporary file in the target's folder (created exclusively, so no link or file of that name is
followed or reused) and then renamed over the target with :func:`os.replace`, which is atomic.
A crash or a full disk therefore leaves either the old file or the new one, never a truncated
one, and a stray ``NAME.tmp`` is never written through. A symbolic link at the target is
refused (the command did not make it; writing would either follow it out of the output folder
or silently replace the user's link), and so is a target that is not a regular file (a folder,
a FIFO, a device).
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any, Literal, overload

from drill_env.validation import printable, shown

__all__ = ["check_writable_target", "replacing", "write_bytes", "write_text"]


def _default_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


_NEW_FILE_MODE = _default_mode()
"""Permissions of a new file: what ``open(path, "w")`` would give under the process's umask."""


def check_writable_target(path: str | os.PathLike[str]) -> Path:
    """``path`` as a ``Path`` if a file may be written there: it does not exist yet or it is
    a regular file (not a symbolic link, even to a regular file; not a folder, FIFO, socket or
    device).

    Raises:
        ValueError: one line naming the path (shown escaped) and what is there.
    """
    p = Path(path)
    try:
        info = p.lstat()
    except FileNotFoundError:
        return p
    if stat.S_ISLNK(info.st_mode):
        raise ValueError(
            f"refusing to write {printable(p, 300)}: it is a symbolic link (remove it or "
            "choose another output)"
        )
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(
            f"refusing to write {printable(p, 300)}: it exists and is not a regular file"
        )
    return p


@overload
def replacing(
    path: str | os.PathLike[str], mode: Literal["w"] = "w", newline: str | None = None
) -> contextlib.AbstractContextManager[IO[str]]: ...
@overload
def replacing(
    path: str | os.PathLike[str], mode: Literal["wb"], newline: None = None
) -> contextlib.AbstractContextManager[IO[bytes]]: ...
def replacing(
    path: str | os.PathLike[str], mode: str = "w", newline: str | None = None
) -> contextlib.AbstractContextManager[IO[Any]]:
    """A context manager opening a new temporary file beside ``path`` (``mode`` ``"w"``, UTF-8
    text, or ``"wb"``) that replaces ``path`` atomically when the block ends without an
    exception; on an exception the temporary file is removed and ``path`` is left as it was.
    The folder of ``path`` is created if needed. A file being replaced keeps its permissions;
    a new one gets those of ``open(path, "w")``.

    Raises:
        ValueError: ``path`` is a symbolic link or not a regular file
            (:func:`check_writable_target`), checked before and again just before renaming.
    """
    return _replacing(Path(path), mode, newline)


@contextlib.contextmanager
def _replacing(path: Path, mode: str, newline: str | None) -> Iterator[IO[Any]]:
    if mode not in ("w", "wb"):
        raise ValueError(f"mode = {shown(mode)} is not a write mode: allowed 'w' or 'wb'")
    check_writable_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name[:100]}.", suffix=".tmp", dir=path.parent)
    tmp = Path(tmp_name)
    try:
        if mode == "wb":
            handle: IO[Any] = os.fdopen(fd, "wb")
        else:
            handle = os.fdopen(fd, "w", encoding="utf-8", newline=newline)
        with handle:
            try:
                file_mode = stat.S_IMODE(path.stat().st_mode)
            except FileNotFoundError:
                file_mode = _NEW_FILE_MODE
            os.fchmod(handle.fileno(), file_mode)
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        check_writable_target(path)  # nothing was put there meanwhile
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`replacing`; returns the path."""
    with replacing(path, "w") as f:
        f.write(text)
    return Path(path)


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` through :func:`replacing`; returns the path."""
    with replacing(path, "wb") as f:
        f.write(data)
    return Path(path)
