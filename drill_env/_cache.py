"""Keep numba's on-disk cache of this package consistent with its sources, and say when it is
being filled.

numba invalidates a cached function only when the function's own file changes, not when a
function it calls (in another file of the package) does; a stale kernel would then run old
physics. At import, this module hashes the package's sources and, when the hash differs from
the one stamped next to the cache, deletes the package's cache files so everything recompiles.
"""

from __future__ import annotations

import contextlib
import hashlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from numba.core import event

__all__ = ["announce_compilation", "invalidate_stale_cache"]


def invalidate_stale_cache(package_dir: Path, *depends_on: Path) -> None:
    """Delete ``package_dir/__pycache__/*.nbi|*.nbc`` when any ``*.py`` of the package, or of
    the packages in ``depends_on`` whose compiled functions it calls, changed."""
    digest = hashlib.sha256()
    for folder in (package_dir, *depends_on):
        for source in sorted(folder.glob("*.py")):
            digest.update(f"{folder.name}/{source.name}".encode())
            digest.update(source.read_bytes())
    cache = package_dir / "__pycache__"
    stamp = cache / "numba-sources.sha256"
    current = digest.hexdigest()
    with contextlib.suppress(OSError):
        if stamp.read_text() == current:
            return
    with contextlib.suppress(OSError):  # read-only installs simply keep numba's own behaviour
        cache.mkdir(exist_ok=True)
        for pattern in ("*.nbi", "*.nbc"):
            for path in cache.glob(pattern):
                path.unlink(missing_ok=True)
        stamp.write_text(current)


_announced: set[str] = set()


@contextlib.contextmanager
def announce_compilation(what: str, about_s: float) -> Iterator[None]:
    """Within the block, say once per process on stderr that ``what`` is being compiled, the
    moment numba starts compiling anything (a miss of its on-disk cache); a block whose code
    is already compiled or cached stays silent."""
    if what in _announced:
        yield
        return

    def on_compile(kind: str, data: object) -> None:  # noqa: ARG001
        if what not in _announced:
            _announced.add(what)
            print(
                f"drill_env: compiling {what} (first use, about {about_s:.0f} s; cached "
                "afterwards)",
                file=sys.stderr,
                flush=True,
            )

    listener = _StartListener(on_compile)
    with event.install_listener("numba:compile", listener):
        yield


class _StartListener(event.Listener):
    """Calls ``callback(kind, data)`` when a numba compilation starts."""

    def __init__(self, callback: Callable[[str, object], None]) -> None:
        self._callback = callback

    def on_start(self, ev: event.Event) -> None:
        self._callback(ev.kind, ev.data)

    def on_end(self, ev: event.Event) -> None:
        pass
