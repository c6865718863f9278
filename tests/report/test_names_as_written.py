"""Names in figures are drawn as written: a segment, joint or marker name holding ``$`` is not read as matplotlib's
math notation (``"knee$\\undefinedcmd{x$"`` had stopped ``plan --figure`` and ``diagnose --plots`` with a parse
error)."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

pytest.importorskip("matplotlib")

from identcheck.report.figure_io import figure, save, svg_text  # noqa: E402


@settings(max_examples=25, deadline=None)
@given(st.text(alphabet="ab$\\{}^_x", min_size=1, max_size=12))
def test_any_name_is_drawn_as_written(tmp_path_factory, name):
    fig = figure(figsize=(3, 2))
    ax = fig.add_subplot()
    ax.set_title(name)
    ax.text(0.5, 0.5, f"{name}\nrevolute(3,2)")
    ax.plot([0, 1], [0, 1], label=name)
    ax.legend()
    path = save(fig, tmp_path_factory.mktemp("fig") / "names.png")
    assert path.stat().st_size > 0
    svg = svg_text(fig)
    shown = name.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    assert shown.strip() == "" or shown.strip() in svg
