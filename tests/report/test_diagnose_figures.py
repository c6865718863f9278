"""The diagnose figures say what they show: samples that cannot show a misfit are missing (not a perfect fit),
titles and bars name the effect's markers in words. (The joint angle on their axes: test_anatomical_angles.)"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from identcheck.io.model import Model
from identcheck.report.diagnose_figures import seen_alone, where_text
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


def test_samples_that_cannot_misfit_are_not_shown():
    """The root with two visible markers and a ball joint's child with one fit them exactly: masked. The same
    segments with enough markers, and a hinge's child with one marker (three coordinates, one unknown), are kept."""
    chain = Skeleton.from_model(MODEL)
    F = 4
    w = np.ones((F, len(chain.labels)))
    root_cols, thigh = chain.seg_markers[chain.root], chain.seg_markers["thigh"]
    w[1, root_cols[2:]] = 0          # frame 1: root with two markers
    w[2, thigh[1:]] = 0              # frame 2: the hip's child with one marker
    w[3, chain.seg_markers["shank"][1:]] = 0   # frame 3: the knee's (hinge) child with one marker
    ok = seen_alone(SimpleNamespace(chain=chain, weights=w))
    assert ok[0].all()
    assert not ok[1, root_cols[:2]].any() and ok[1, thigh].all()
    assert not ok[2, thigh[:1]].any()
    assert ok[3, chain.seg_markers["shank"][:1]].all()


def test_where_reads_as_words():
    text = where_text({"markers": ["RANK", "RTIB"], "segment": "shank", "joint": "knee", "frames": [1, 2],
                       "amplitude_mm": 3.14159})
    assert text == "markers RANK, RTIB; segment shank; joint knee; amplitude mm 3.14"
    assert "[" not in text and "'" not in text


def test_an_evidence_figures_labels_lie_inside_it():
    """A two-line joint-angle label, a long y label and title: once laid out, the axis labels, the title and the
    legend are inside the canvas (nothing clipped)."""
    from types import SimpleNamespace

    from identcheck.report.diagnose_figures import evidence_figure

    x = np.linspace(-5, 40, 300)
    step = SimpleNamespace(name="soft_tissue", where={"markers": ["RTH3"], "segment": "thigh_r", "joint": "hip_r"},
                           gap_before=3.79, gap_after=3.62, evidence={
                               "x": x, "x_label": "hip_r flexion–extension (deg)\nabout knee_r's hinge axis; 0 at the "
                                                  "ISB pelvis neutral",
                               "y": np.abs(np.sin(x / 10)) * 5, "y_after": np.ones(300),
                               "y_label": "RTH3 residual on thigh_r (mm)", "kind": "scatter"})
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = evidence_figure(step)
    canvas = FigureCanvasAgg(fig)
    fig.tight_layout()
    canvas.draw()
    box = fig.bbox
    ax = fig.axes[0]
    for text in [ax.xaxis.label, ax.yaxis.label, ax.title, *ax.get_legend().get_texts()]:
        ext = text.get_window_extent(renderer=canvas.get_renderer())
        assert ext.x0 >= box.x0 - 1 and ext.x1 <= box.x1 + 1 and ext.y0 >= box.y0 - 1 and ext.y1 <= box.y1 + 1, \
            text.get_text()
