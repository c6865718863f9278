"""A link whose three markers lie on one line counts as two in the closed forms (:func:`identcheck.estimate.
closed_forms.fit_model`): its case is named for what poses it, the estimator is chosen for that case, and the joint
comes out where the simulation put it."""
from __future__ import annotations

import numpy as np
import pytest

import identcheck as ic
from identcheck.estimate.closed_forms import fit_model
from identcheck.io.model import Model

MODEL = """
units = "mm"
[segments.thigh]
markers = ["T1", "T2", "T3"]
length_mm = 420
[segments.thigh.positions]
T1 = [40.0, 30.0, -100.0]
T2 = [-35.0, 40.0, -250.0]
T3 = [45.0, -30.0, -380.0]
[segments.shank]
markers = ["S1", "S2", "S3"]
length_mm = 400
[segments.shank.positions]
S1 = [45.0, 0.0, -80.0]
S2 = [45.0, {off}, -230.0]
S3 = [45.0, 0.0, -380.0]
[joints.knee]
type = "revolute"
parent = "thigh"
child = "shank"
"""


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_shank_with_its_markers_on_a_line_is_a_two_point_link(tmp_path, seed):
    path = tmp_path / "line_shank.toml"
    path.write_text(MODEL.format(off=0.5))
    sim = ic.simulate(path, n_frames=600, noise_mm=0.5, seed=seed)
    fitted, _ = fit_model(Model.from_toml(path), sim.trial)
    est, info = fitted["knee"]
    assert info["case"] == "revolute(3,2)"                # three thigh markers pose the thigh, the shank's two
    assert est is not None and est.unique
    truth = sim.truth.marker_distances("knee")
    world = sim.trial.as_array()
    idx = {m: i for i, m in enumerate(sim.trial.labels)}
    virtual = est.virtual_markers("knee")
    a, b = virtual["knee.axis0"], virtual["knee.axis1"]
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    for m, d in truth.items():
        p = world[:, idx[m]] - a
        dist = np.nanmedian(np.linalg.norm(p - np.sum(p * u, axis=1, keepdims=True) * u, axis=1))
        assert abs(dist - d) < 4.0, (m, dist, d)      # the closed form; the whole-tree fit refines it


def test_the_same_shank_off_its_line_is_three_points(tmp_path):
    path = tmp_path / "plane_shank.toml"
    path.write_text(MODEL.format(off=40.0))
    sim = ic.simulate(path, n_frames=600, noise_mm=0.5, seed=1)
    fitted, _ = fit_model(Model.from_toml(path), sim.trial)
    assert fitted["knee"][1]["case"] == "revolute(3,3)"
