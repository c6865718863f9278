"""A model segment without markers that no joint points pose (a foot without markers): ``diagnose`` leaves the joint
above it, and everything below, out as ``fit`` does, diagnoses the rest, reports the joints left out as undetermined
with why, and says so on standard error. It had refused the whole model (exit 2), the documentation's own example
among them, where ``fit`` answered for the hip and knee."""
from __future__ import annotations

import json

import pytest

from identcheck import cli


@pytest.mark.parametrize("seed", [0, 5])
def test_a_markerless_foot_is_left_out_and_the_rest_diagnosed(tmp_path, capsys, examples, seed):
    model = tmp_path / "leg_bare_foot.toml"
    text = (examples / "leg.toml").read_text().replace('markers = ["RHEE", "RTOE"]', "markers = []")
    assert text != (examples / "leg.toml").read_text()
    model.write_text(text)
    trial = tmp_path / "t.c3d"
    assert cli.main(["simulate", str(model), "--out", str(trial), "--frames", "300", "--noise-mm", "0.5",
                     "--seed", str(seed)]) == 0
    capsys.readouterr()
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) in (0, 1)
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert "Traceback" not in out.err and "ankle_r left out" in out.err and "foot_r" in out.err
    ankle = doc["joints"]["ankle_r"]
    assert ankle["practical"]["verdict"] == "undetermined" and not ankle["unique"]
    assert ankle["marker_distances"] == {} and ankle["uncertainty_mm"] is None and ankle["geometry"] is None
    assert "segments.foot_r.markers: none" in ankle["practical"]["reason"]
    assert doc["joints"]["hip_r"]["practical"]["verdict"] == "determined"
    assert doc["joints"]["hip_r"]["marker_distances"]
    assert cli.main(["diagnose", str(model), str(trial)]) in (0, 1)              # the text report takes it too
    assert "ankle_r" in capsys.readouterr().out


def test_a_markerless_root_is_named_as_the_models(tmp_path, capsys):
    """Nothing can be left out in its place: refused (exit 2) by the root's field, saying what to do."""
    model = tmp_path / "bare_root.toml"
    model.write_text('units = "mm"\n[segments.pelvis]\nmarkers = []\n[segments.thigh]\nmarkers = ["A", "B", "C"]\n'
                     '[joints.hip]\ntype = "spherical"\nparent = "pelvis"\nchild = "thigh"\n')
    trial = tmp_path / "t.c3d"
    assert cli.main(["simulate", str(model), "--out", str(trial), "--frames", "200", "--noise-mm", "0.3"]) in (0, 2)
    capsys.readouterr()
    if not trial.exists():
        pytest.skip("simulate refuses the model")
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) == 2
    err = capsys.readouterr().err
    assert "bare_root.toml" in err and "Traceback" not in err
