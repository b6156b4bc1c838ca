"""Keep numba's on-disk cache of this package consistent with its sources.

numba invalidates a cached function only when the function's own file changes, not when a
function it calls (in another file of the package) does; a stale kernel would then run old
physics. At import, this module hashes the package's sources and, when the hash differs from
the one stamped next to the cache, deletes the package's cache files so everything recompiles.
"""

from __future__ import annotations

import contextlib
import hashlib
from pathlib import Path

__all__ = ["invalidate_stale_cache"]


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
