"""matplotlib, off-screen: every picture of the package (training curves, the speed–accuracy chart)
is drawn to PNG files through :func:`pyplot`. matplotlib is an optional dependency (the
``[train]`` extra)."""

from __future__ import annotations

from typing import Any


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg (file-only) backend.

    Raises:
        ImportError: matplotlib is not installed (with the install command).
    """
    try:
        import matplotlib
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError("plots need matplotlib: pip install 'usd-garment[train]'") from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
