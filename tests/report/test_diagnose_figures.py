"""The diagnose figures say what they show: a ball joint's axis is the angle it turned most (not one component of
a rotation vector), samples that cannot show a misfit are missing (not a perfect fit), titles and bars name the
effect's markers in words."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.hypothesis import main_angle
from identcheck.io.model import Model
from identcheck.report.diagnose_figures import seen_alone, where_text
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


def _ball(rel_R):
    chain = SimpleNamespace(joints=["hip"], types={"hip": "spherical"})
    return SimpleNamespace(fit=SimpleNamespace(state=SimpleNamespace(rel_R={"hip": rel_R}, theta={}), chain=chain))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), amp=st.floats(10, 60), wobble=st.floats(0, 3))
def test_a_ball_joints_axis_is_its_main_rotation(seed, amp, wobble):
    """A ball joint turning by ±amp degrees about a random axis (plus a few degrees about the others): the figure's
    angle spans 2·amp within the wobble, and the label names that axis in the parent's frame."""
    rng = np.random.default_rng(seed)
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    base = Rotation.random(random_state=rng)
    t = np.linspace(0, 4 * np.pi, 800)
    rv = np.outer(np.deg2rad(amp) * np.sin(t), axis) + np.deg2rad(wobble) * rng.standard_normal((800, 3)) / 3
    rel = (Rotation.from_rotvec(rv) * base).as_matrix()
    x, label = main_angle(_ball(rel), "hip")
    assert abs(np.ptp(x) - 2 * amp) <= 0.1 * amp + 4 * wobble
    shown = np.array([float(v) for v in label.split("(")[1].split(")")[0].split(",")])
    assert abs(abs(shown @ axis) - 1) < 0.05 + 0.1 * wobble / amp
    assert "parent's frame" in label


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
