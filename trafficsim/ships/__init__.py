"""Ship models, the ship library and standard manoeuvres.

Compiled kernels are cached on disk in a folder named after a hash of this package's sources:
numba's own cache only notices edits to a kernel's own file, not to the functions it calls in
other modules, so keying the folder on every source makes a stale kernel impossible. Set
``NUMBA_CACHE_DIR`` to choose the parent folder (default ``~/.cache/trafficsim``).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


def _kernel_cache_dir() -> Path:
    here = Path(__file__).parent
    digest = hashlib.sha1()
    for src in sorted(here.glob("*.py")):
        digest.update(src.name.encode())
        digest.update(src.read_bytes())
    parent = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "trafficsim")
    return Path(parent) / f"kernels-{digest.hexdigest()[:16]}"


def _configure_numba_cache() -> None:
    import numba

    numba.config.CACHE_DIR = str(_kernel_cache_dir())


_configure_numba_cache()
