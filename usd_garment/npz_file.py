"""Reading a whole ``.npz`` file, with one clear error for a file that is not one."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_npz(
    path: str | Path, unreadable: str, error: type[Exception] = ValueError
) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` file ``path`` by name (no pickled objects).

    Raises:
        error: the file cannot be read as an ``.npz`` (missing, truncated, not a zip), with the
            message ``"{path}: {unreadable} ({reason})"``.
    """
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (OSError, ValueError, EOFError) as exc:
        raise error(f"{path}: {unreadable} ({exc})") from exc
