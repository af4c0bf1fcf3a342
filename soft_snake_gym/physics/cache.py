"""Keep numba's on-disk cache honest across files.

numba caches a compiled function next to its source (``__pycache__/<module>.<name>-<line>.*.nbi``
and ``.nbc``) and invalidates it when *that* source file changes, but not when a compiled
function it calls from *another* file changes: the cached caller keeps the old callee's machine
code. Every module whose kernels call kernels of other files calls :func:`drop_stale_cache` at
import with the files it depends on; when their content differs from the content recorded at
the last import, the module's cached machine code is deleted and numba compiles it afresh.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["drop_stale_cache"]


def drop_stale_cache(module_file: str, dependencies: list[str]) -> bool:
    """Delete the numba cache of ``module_file`` if any file in ``dependencies`` changed.

    The content hash of the dependencies is recorded in ``__pycache__/<module>.deps``. Only the
    default cache location (``__pycache__`` beside the source) is handled; with
    ``NUMBA_CACHE_DIR`` set, delete stale caches there by hand after editing a kernel.

    Returns:
        True if cached files were deleted (or the record was missing).
    """
    src = Path(module_file)
    cache_dir = src.parent / "__pycache__"
    digest = hashlib.sha256()
    for dep in sorted(dependencies):
        digest.update(Path(dep).read_bytes())
    stamp = cache_dir / f"{src.stem}.deps"
    try:
        if stamp.read_text() == digest.hexdigest():
            return False
    except OSError:
        pass
    for pattern in (f"{src.stem}.*.nbi", f"{src.stem}.*.nbc"):
        for cached in cache_dir.glob(pattern):
            cached.unlink(missing_ok=True)
    try:
        cache_dir.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:  # a read-only install: numba cannot cache there either
        pass
    return True
