"""Matplotlib for the figures of the report and of ``qc`` (private, imported lazily).

Both packages draw with the Agg backend and embed each figure as PNG bytes, so
nothing touches the display or the network.
"""

from __future__ import annotations

import io
from typing import Any

__all__ = ["pyplot", "png"]


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (the ``report`` extra is required)."""
    from ._validate import require

    mpl = require("matplotlib", "report")
    mpl.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def png(fig: Any) -> bytes:
    """The figure as PNG bytes (100 dpi, tight box); the figure is closed."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    pyplot().close(fig)
    return buf.getvalue()
