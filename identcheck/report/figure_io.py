"""Figures drawn with matplotlib's object API: a :class:`matplotlib.figure.Figure` of its own, saved with
``savefig``.

No backend is selected and pyplot's global state is never touched, so drawing a figure here leaves a
notebook's inline backend (or any other) as it was; a returned Figure displays in a notebook like any
other. matplotlib is imported only when a figure is drawn (the ``plots`` extra).
"""
from __future__ import annotations

from pathlib import Path

from identcheck.io.atomic import replacing


def figure(**kw):
    """A new :class:`matplotlib.figure.Figure` (keywords as for it, e.g. ``figsize``), owned by the caller."""
    from matplotlib.figure import Figure

    return Figure(**kw)


def as_written(fig) -> None:
    """Every text of ``fig`` drawn as written, never read as matplotlib's math notation: the figures show the names
    of a model's segments, joints and markers, and a name holding ``$`` (``"knee$\\undefinedcmd{x$"``) had stopped
    ``plan --figure`` and ``diagnose --plots`` with a parse error. (None of identcheck's own labels uses the
    notation.)"""
    from matplotlib.text import Text

    for text in fig.findobj(Text):
        text.set_parse_math(False)


def save(fig, path, dpi: int = 110, rect=None) -> Path:
    """Lay out ``fig`` (within ``rect``, figure fraction, when room is kept for a legend) and write it to
    ``path`` (PNG/SVG by extension); returns the path."""
    as_written(fig)
    fig.tight_layout(rect=rect)
    with replacing(path) as tmp:
        fig.savefig(tmp, dpi=dpi)           # the temporary name keeps the ending that chooses the format
    return Path(path)


def svg_text(fig, rect=None) -> str:
    """``fig`` laid out (as :func:`save`) and drawn as SVG text with no date stamp and fixed element ids, so that
    the same figure gives the same text: what an HTML page inlines."""
    import io

    from matplotlib import rc_context

    as_written(fig)
    fig.tight_layout(rect=rect)
    buf = io.StringIO()
    with rc_context({"svg.hashsalt": "identcheck", "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg", metadata={"Date": None})
    text = buf.getvalue()
    return text[text.index("<svg"):]          # the element alone, without the XML prolog and DOCTYPE
