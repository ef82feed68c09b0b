"""Feather (Arrow IPC) tables read with pyarrow, with errors that name the file, the column and
the byte where a cut-off file ends."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError

__all__ = ["read_feather_columns", "rotations_from_wxyz"]

_MAGIC = b"ARROW1"


def _damage(path: Path, size: int) -> str | None:
    """What is wrong with the Arrow IPC framing of ``path`` (magic at both ends), or None."""
    with path.open("rb") as fh:
        head = fh.read(len(_MAGIC))
        if head != _MAGIC:
            return f"byte 0 holds {head!r}, not the Arrow IPC magic {_MAGIC!r}: not a Feather file"
        if size < 2 * len(_MAGIC):
            return f"it ends at byte {size}, before its footer: the file is cut off"
        fh.seek(size - len(_MAGIC))
        if fh.read(len(_MAGIC)) != _MAGIC:
            return (
                f"it ends at byte {size} without the Arrow IPC footer (magic {_MAGIC!r} at its "
                "last bytes): the file is cut off"
            )
    return None


def read_feather_columns(path: Path, columns: Sequence[str]) -> dict[str, npt.NDArray[Any]]:
    """The ``columns`` of the Feather table at ``path`` as numpy arrays (strings as object
    arrays); optional columns absent from the file are left out only when not in ``columns``.

    Raises:
        LogError: missing, unreadable, cut off or damaged, or a column is missing.
    """
    import pyarrow as pa
    from pyarrow import feather

    try:
        size = path.stat().st_size
        damage = _damage(path, size)
    except OSError as err:
        msg = f"{path}: cannot read ({err.strerror}); restore the file"
        raise LogError(msg) from err
    if damage is not None:
        msg = f"{path}: {damage}; restore it"
        raise LogError(msg)
    try:
        table = feather.read_table(path)
    except (pa.ArrowException, OSError, ValueError) as err:
        msg = f"{path}: the Arrow IPC table ({size} bytes) is damaged ({err}); restore it"
        raise LogError(msg) from err
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        msg = (
            f"{path}: no column {', '.join(missing)} (it has {', '.join(table.column_names)}); "
            "not the Argoverse 2 layout, or a damaged table"
        )
        raise LogError(msg)
    out: dict[str, npt.NDArray[Any]] = {}
    for name in table.column_names:
        column = table.column(name)
        if column.null_count and name in columns:
            row = int(np.flatnonzero(np.asarray(column.is_null()))[0])
            msg = f"{path}: column {name} row {row} is null; the table is damaged, restore it"
            raise LogError(msg)
        out[name] = column.to_numpy(zero_copy_only=False)
    return out


def rotations_from_wxyz(q_wxyz: npt.NDArray[np.float64], *, what: str) -> npt.NDArray[np.float64]:
    """(N, 3, 3) rotation matrices of (N, 4) quaternions w, x, y, z (normalised).

    Raises:
        LogError: a quaternion is not finite or of zero length (``what`` and its row say where).
    """
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~np.isfinite(norms) | (norms < 1e-9))
    if bad.size:
        msg = f"{what}: row {int(bad[0])} holds quaternion {q[bad[0]].tolist()}, not a rotation"
        raise LogError(msg)
    w, x, y, z = (q / norms[:, None]).T
    out = np.empty((len(q), 3, 3))
    out[:, 0, 0] = 1 - 2 * (y * y + z * z)
    out[:, 0, 1] = 2 * (x * y - w * z)
    out[:, 0, 2] = 2 * (x * z + w * y)
    out[:, 1, 0] = 2 * (x * y + w * z)
    out[:, 1, 1] = 1 - 2 * (x * x + z * z)
    out[:, 1, 2] = 2 * (y * z - w * x)
    out[:, 2, 0] = 2 * (x * z - w * y)
    out[:, 2, 1] = 2 * (y * z + w * x)
    out[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return out
