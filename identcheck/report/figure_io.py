"""Figures drawn with matplotlib's object API: a :class:`matplotlib.figure.Figure` of its own, saved with
``savefig``.

No backend is selected and pyplot's global state is never touched, so drawing a figure here leaves a
notebook's inline backend (or any other) as it was; a returned Figure displays in a notebook like any
other. matplotlib is imported only when a figure is drawn (the ``plots`` extra).
"""
from __future__ import annotations

from pathlib import Path


def figure(**kw):
    """A new :class:`matplotlib.figure.Figure` (keywords as for it, e.g. ``figsize``), owned by the caller."""
    from matplotlib.figure import Figure

    return Figure(**kw)


def save(fig, path, dpi: int = 110, rect=None) -> Path:
    """Lay out ``fig`` (within ``rect``, figure fraction, when room is kept for a legend) and write it to
    ``path`` (PNG/SVG by extension); returns the path."""
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=dpi)
    return Path(path)
