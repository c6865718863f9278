"""``diagnose`` on a leg whose thigh carries two markers (an anatomical layout: a lateral thigh marker and the
epicondyle): its rigid fit starts from the closed-form joints (:func:`identcheck.bundle.start.start_state`), since the
thigh's own two markers cannot pose it. Before, it refused: "segment 'thigh' has 2 marker(s): diagnose needs three or
more on every segment"."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from identcheck.diagnose.workflow import diagnose
from identcheck.effects.registry import inject_effect
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial

MODEL = """units = "mm"
[segments.pelvis]
markers = ["LASI", "RASI", "SACR"]
[segments.thigh]
markers = ["RTHI", "RKNE"]
length_mm = 420
[segments.shank]
markers = ["RTIB", "RTIB2", "RANK"]
length_mm = 400
[joints.hip]
type = "spherical"
parent = "pelvis"
child = "thigh"
[joints.knee]
type = "revolute"
parent = "thigh"
child = "shank"
"""


def _diagnosed(tmp_path, seed: int, effect: str | None):
    path = tmp_path / "two_marker_thigh.toml"
    path.write_text(MODEL)
    model = Model.from_toml(path)
    sim = simulate(model, n_frames=500, noise_mm=0.5, seed=seed)
    if effect:
        sim = inject_effect(sim, effect, seed=seed)
    trc = tmp_path / "trial.trc"
    sim.trial.to_file(trc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sim, diagnose(model, Trial.from_file(trc)).to_dict()


@pytest.mark.parametrize("seed", [1, 2])
def test_a_clean_leg_with_a_two_marker_thigh_is_diagnosed_clean(tmp_path, seed):
    _, rep = _diagnosed(tmp_path, seed, None)
    assert rep["effects"] == []
    assert rep["gap_after"] <= 1.5 * rep["noise_floor"]
    assert set(rep["joints"]) == {"hip", "knee"}


def test_a_slip_beside_a_two_marker_thigh_is_named_where_it_is(tmp_path):
    sim, rep = _diagnosed(tmp_path, 4, "marker_slip")
    names = [e["name"] for e in rep["effects"]]
    assert names and names[0] == "marker_slip"
    assert rep["effects"][0]["where"]["markers"] == sim.settings["effect"]["where"]["markers"]
    assert np.isfinite(rep["gap_after"]) and rep["gap_after"] <= 1.5 * rep["noise_floor"]
