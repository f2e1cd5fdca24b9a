"""Tables from HDF5 files: a group whose one-dimensional datasets are the columns, or a
compound (table) dataset whose fields are, read with h5py (an optional dependency:
``pip install "bodyfusion[hdf5]"``).

A layout reads one by giving a table section ``group`` beside its ``path``
(:class:`~bodyfusion.base.sections.TableSection`): the section's column names are then the
datasets of that group (``acc_x``...) or the fields of that dataset; every column must be
numeric and all of one length.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.extras import import_optional
from bodyfusion.base.files import file_problem


def read_group(path: str | Path, group: str, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """``columns`` of the HDF5 file ``path``: the one-dimensional datasets named so in ``group``,
    or the fields of the compound dataset ``group``, as float64. Errors name the file and
    group: a group or dataset that is not there (what is there listed), a column of another
    length or not a number."""
    h5py = import_optional("h5py", "hdf5", "reading an HDF5 file")
    path = Path(path)
    if (problem := file_problem(path)) is not None:
        raise InputError(path, problem)
    try:
        with h5py.File(path, "r") as f:
            if group not in f:
                raise InputError(path, f"no group or dataset {group!r} (it has {', '.join(sorted(f)) or 'none'})")
            node = f[group]
            if isinstance(node, h5py.Dataset):
                names = node.dtype.names or ()
                have, take = list(names), (lambda c: node.fields(c)[:])
            else:
                have, take = sorted(k for k in node if isinstance(node[k], h5py.Dataset)), (lambda c: node[c][:])
            missing = [c for c in columns if c not in have]
            if missing:
                raise InputError(path, f"{group}: no column(s) {', '.join(missing)} (it has {', '.join(have) or 'none'})")
            out = {}
            for c in columns:
                values = np.asarray(take(c))
                if values.ndim != 1 or not np.issubdtype(values.dtype, np.number):
                    raise InputError(path, f"{group}/{c}: not a one-dimensional numeric column ({values.dtype}, "
                                           f"shape {values.shape})")
                out[c] = np.ascontiguousarray(values, dtype=np.float64)
    except OSError as err:
        raise InputError(path, f"not an HDF5 file: {err}") from None
    lengths = {len(v) for v in out.values()}
    if len(lengths) > 1:
        raise InputError(path, f"{group}: its columns differ in length ({', '.join(map(str, sorted(lengths)))})")
    return out
