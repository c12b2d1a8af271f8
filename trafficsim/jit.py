"""The one decorator for compiled kernels: ``@kernel`` = numba ``njit`` with an on-disk cache.

Kernels use numpy's error model: a division by zero gives inf or NaN as IEEE 754 says instead
of raising ``ZeroDivisionError``. Numba's default Python model tests every divisor, which keeps
the compiler from optimising the arithmetic around it (the Nomoto RK4 step costs a quarter
more); the kernels keep their divisors away from zero themselves, and any other result is the
same to the bit.

Compiled code is cached in a folder named after a hash of all of trafficsim's sources: numba's
own cache notices edits to a kernel's own file only, not to the functions it calls in other
modules, so keying the folder on every source makes a stale kernel impossible. Set
``NUMBA_CACHE_DIR`` to choose the parent folder (default ``~/.cache/trafficsim``).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba

_PACKAGE = Path(__file__).parent


def kernel_cache_dir() -> Path:
    """Cache folder for this exact set of sources."""
    digest = hashlib.sha1()
    for src in sorted(_PACKAGE.rglob("*.py")):
        digest.update(str(src.relative_to(_PACKAGE)).encode())
        digest.update(src.read_bytes())
    parent = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "trafficsim")
    return Path(parent) / f"kernels-{digest.hexdigest()[:16]}"


numba.config.CACHE_DIR = str(kernel_cache_dir())

#: decorator for every compiled function of the package
kernel = numba.njit(cache=True, error_model="numpy")

#: decorator for small compiled helpers that their calling kernels must inline (a branch to an
#: out-of-line helper can keep the compiler from optimising the caller's common path)
inline_kernel = numba.njit(cache=True, inline="always", error_model="numpy")
