"""A segment whose own markers and the ball centre above it lie on one line is not posed by them: its roll about
that line is left to the noise (two thigh markers along the femur's line through the hip's centre), as with one
marker. The count alone (two markers and a centre: three points) had called it posed."""
from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain
from identcheck.bundle.honest import posed_above, posed_by_itself
from identcheck.bundle.start import start_state
from identcheck.fit.whole_tree import skeleton_of
from identcheck.geometry.poses import off_line_mm, OFF_LINE_MM
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = """
units = "mm"
[segments.pelvis]
markers = ["RASI", "LASI", "RPSI"]
[segments.thigh]
markers = ["RTHI", "RKNE"]
length_mm = 420
[segments.thigh.positions]
RTHI = [{a}, {b}, -200.0]
RKNE = [{c}, {d}, -400.0]
[segments.shank]
markers = ["RTIB", "RANK", "RMED"]
length_mm = 400
[segments.shank.positions]
RTIB = [30.0, 45.0, -150.0]
RANK = [50.0, 0.0, -385.0]
RMED = [-40.0, 10.0, -380.0]
[joints.hip]
type = "spherical"
parent = "pelvis"
child = "thigh"
[joints.knee]
type = "revolute"
parent = "thigh"
child = "shank"
"""


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10 ** 5), offsets=st.tuples(*[st.floats(-30.0, 30.0)] * 4))
def test_a_thigh_is_posed_by_two_markers_and_the_hip_only_off_one_line(tmp_path_factory, seed, offsets):
    """Random places of two thigh markers, some within millimetres of the line through the hip's centre: the
    thigh is posed by itself, given the fit, exactly when its markers and the fitted centre are
    :data:`OFF_LINE_MM` or more off one line (the simulator's truth, within 1 mm of the fitted places); the count
    alone always says posed, and the knee below is posed above only when the thigh is."""
    a, b, c, d = (x if abs(x) > 6.0 else x / 20.0 for x in offsets)       # half of them nearly on the line
    path = tmp_path_factory.mktemp("line") / "thigh.toml"
    path.write_text(MODEL.format(a=a, b=b, c=c, d=d))
    model = Model.from_toml(path)
    sim = simulate(model, n_frames=300, noise_mm=0.3, seed=seed)
    chain = skeleton_of(model, sim.trial)
    data = sim.trial.select(chain.labels).as_array()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_chain(chain, data, start_state(model, chain, data, sim.trial.rate_hz), max_iter=100)
    truth = np.array([[0.0, 0.0, 0.0], [a, b, -200.0], [c, d, -400.0]])
    off = off_line_mm(truth[None])
    assert posed_by_itself(chain, "thigh")
    if abs(off - OFF_LINE_MM) > 1.0:
        assert posed_by_itself(chain, "thigh", fit) == (off >= OFF_LINE_MM)
    assert posed_above(chain, "knee", fit) == posed_by_itself(chain, "thigh", fit)
    assert posed_by_itself(chain, "pelvis", fit) and posed_by_itself(chain, "shank", fit)
