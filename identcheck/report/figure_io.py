"""Figures written to files without a display: the headless pyplot, and saving that frees the figure."""
from __future__ import annotations

from pathlib import Path


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed; imported only when a figure is drawn)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save(fig, path, dpi: int = 110, rect=None) -> Path:
    """Lay out (within ``rect``, figure fraction, when room is kept for a legend), write (PNG/SVG by
    extension) and close ``fig``; returns the path."""
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)
    return Path(path)
