"""The one decorator for compiled kernels: ``@kernel`` = numba ``njit`` with an on-disk cache.

Kernels use numpy's error model: a division by zero gives inf or NaN as IEEE 754 says instead
of raising ``ZeroDivisionError``. Numba's default Python model tests every divisor, which keeps
the compiler from optimising the arithmetic around it (the Nomoto RK4 step costs a quarter
more); the kernels keep their divisors away from zero themselves, and any other result is the
same to the bit.

Compiled code is cached in a folder named after a hash of all of trafficsim's sources: numba's
own cache notices edits to a kernel's own file only, not to the functions it calls in other
modules, so keying the folder on every source makes a stale kernel impossible. Set
``NUMBA_CACHE_DIR`` to choose the parent folder (default ``~/.cache/trafficsim``). Each import
marks its folder as used; folders of other sources (older versions, edits) unused for
:data:`STALE_DAYS` days are deleted, so the cache does not grow with every upgrade.

A loop over ships reads and writes many arrays (state rows, parameter columns, commands). The
compiler vectorises such a loop only after testing at run time that the arrays it writes do not
overlap those it reads, and by default gives up beyond 128 such tests; the limit is raised to
:data:`MEMORY_CHECKS` (the tests cost a few hundred nanoseconds per call, the vectorised loop
saves microseconds per hundred ships). The results are the same to the bit either way.

:func:`prefetch` asks the cache for an element a loop will use a few iterations later: for
loops that touch scattered records (a tracker's history, the buffer slot of a ship that may
send an AIS report), which the hardware's own prefetching does not foresee.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import time
from pathlib import Path

import llvmlite.binding
import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

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


#: a kernel folder of other sources unused for this long is deleted
STALE_DAYS = 30.0


def prune_stale(current: Path, now: float | None = None) -> None:
    """Mark ``current`` as used now, and delete the other ``kernels-*`` folders beside it that
    have not been used for :data:`STALE_DAYS` (best effort: a folder in use by another process
    or not ours to delete stays)."""
    now = time.time() if now is None else now
    try:
        current.mkdir(parents=True, exist_ok=True)
        os.utime(current, (now, now))
        folders = list(current.parent.glob("kernels-*"))
    except OSError:  # a read-only home: numba then caches nothing, as before
        return
    for folder in folders:
        with contextlib.suppress(OSError):  # (another process may be deleting it too)
            if folder != current and now - folder.stat().st_mtime > STALE_DAYS * 86400.0:
                shutil.rmtree(folder)


#: run-time overlap tests the compiler may emit to vectorise a loop (its default: 128)
MEMORY_CHECKS = 4096
llvmlite.binding.set_option("trafficsim", f"-vectorize-memory-check-threshold={MEMORY_CHECKS}")

numba.config.CACHE_DIR = str(kernel_cache_dir())
prune_stale(Path(numba.config.CACHE_DIR))

#: decorator for every compiled function of the package
kernel = numba.njit(cache=True, error_model="numpy")

#: decorator for small compiled helpers that their calling kernels must inline (a branch to an
#: out-of-line helper can keep the compiler from optimising the caller's common path)
inline_kernel = numba.njit(cache=True, inline="always", error_model="numpy")


@intrinsic
def prefetch(typingctx: object, a: types.Array, i: types.Integer) -> tuple:
    """Ask the cache for element ``i`` of the 1-d array ``a``, to be written soon
    (``llvm.prefetch``: a hint, it changes no result)."""
    def codegen(context: object, builder: ir.IRBuilder, sig: object, args: list) -> object:
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        ptr = builder.bitcast(
            cgutils.get_item_pointer(context, builder, sig.args[0], ary, [args[1]]),
            ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [ptr.type, i32, i32, i32]),
            "llvm.prefetch.p0")
        # write, keep in all cache levels, data cache
        builder.call(fn, [ptr, ir.Constant(i32, 1), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()
    return types.void(a, types.intp), codegen
