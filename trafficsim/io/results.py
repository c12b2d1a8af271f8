"""Result files written atomically: temp file in the same folder, flush, fsync, rename.

A crash never leaves a half-written result behind: a reader sees the old file or the new one.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from trafficsim.errors import DataError


def plain_mode(path: str | os.PathLike[str]) -> None:
    """Give a temp file the permissions ``open()`` would have given it (0666 less the umask),
    not ``mkstemp``'s 0600, before it is renamed into place."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def atomic_write(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` via ``write(fileobj)`` on a temp file, then rename over ``path`` (with the
    permissions of a plain ``open``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        plain_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _unknown(value: Any) -> Any:
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """Atomically write ``data`` as indented JSON (NaN/inf become null, also inside numpy
    arrays; numpy scalars become plain numbers)."""
    text = json.dumps(_clean(data), indent=2, default=_unknown, allow_nan=False) + "\n"
    atomic_write(path, lambda fh: fh.write(text.encode()))


def _clean(value: Any) -> Any:
    if isinstance(value, (np.ndarray, np.generic)):
        value = value.tolist()  # plain Python values, nested lists for arrays
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def write_parquet(path: Path, columns: Mapping[str, Any]) -> None:
    """Atomically write a table of equal-length columns as Parquet."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({k: np.asarray(v) if not isinstance(v, list) else v
                      for k, v in columns.items()})
    atomic_write(path, lambda fh: pq.write_table(table, fh))


def read_parquet(path: Path, what: str = "table", columns: Sequence[str] = (),
                 only: bool = False) -> Any:
    """The ``pyarrow.Table`` in ``path`` (with ``only``, just ``columns``).

    Raises:
        DataError: naming the file, if it does not read (pyarrow raises several types for
            damaged files) or lacks any of ``columns``.
    """
    import pyarrow.parquet as pq

    try:
        missing = [c for c in columns if c not in pq.read_schema(path).names]
        if missing:
            raise DataError(f"columns missing: {', '.join(missing)} (written by an older "
                            "trafficsim? run it again)", path=str(path))
        return pq.read_table(path, columns=list(columns) if only else None)
    except DataError:
        raise
    except Exception as err:
        raise DataError(f"unreadable {what} ({err})", path=str(path)) from None


#: column-name endings of bearings in [0, 360) deg: a value the format rounds up to 360 is 0
BEARING_SUFFIXES = ("heading_deg", "cog_deg")


def write_csv(path: Path, columns: Mapping[str, np.ndarray], fmt: str = "%.6g") -> None:
    """Atomically write equal-length numeric columns as CSV with a header row (bearings stay
    below 360 as written, :data:`BEARING_SUFFIXES`)."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], dtype=float) for k in names])
    for j, name in enumerate(names):
        if name.endswith(BEARING_SUFFIXES) and data.shape[0]:
            shown = np.char.mod(fmt, data[:, j]).astype(float)
            data[shown >= 360.0, j] = 0.0

    def write(fh: IO[bytes]) -> None:
        fh.write((",".join(names) + "\n").encode())
        np.savetxt(fh, data, delimiter=",", fmt=fmt)

    atomic_write(path, write)


def check_numeric(table: Any, path: Path, columns: Sequence[str]) -> None:
    """Raise :class:`DataError` naming the file and the column if one of ``columns`` of a
    ``pyarrow.Table`` does not hold numbers (floats, integers, or booleans without gaps)."""
    import pyarrow.types as pat

    for name in columns:
        kind = table.schema.field(name).type
        if pat.is_boolean(kind) and table.column(name).null_count:
            raise DataError("expected true or false in every row, got empty values", path=str(path),
                            key=name)
        if not (pat.is_integer(kind) or pat.is_floating(kind) or pat.is_boolean(kind)):
            raise DataError(f"expected numbers, got {kind} values (written by another program? "
                            "run it again)", path=str(path), key=name)
