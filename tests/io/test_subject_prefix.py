"""Vicon's ``Subject:Marker`` labels against a model that names its markers ``RASI``: one common prefix that makes
every model marker match is removed, with a warning naming it; anything else is left to ``require_usable``, whose
message names the prefixed labels."""
import json

import numpy as np
import pytest

import identcheck.api as api
from identcheck.cli import main
from identcheck.errors import InputError
from identcheck.trial import Trial

PREFIX = "Jane Doe:"


def _prefixed(sim, prefix=PREFIX, keep=()):
    """The simulated trial with every label but those in `keep` behind `prefix`."""
    t = sim.trial
    return t.replace(labels=[lab if lab in keep else prefix + lab for lab in t.labels])


@pytest.fixture(scope="module")
def leg(examples):
    return api.simulate(examples / "leg.toml", seed=3, noise_mm=0.4, n_frames=150)


def test_unprefixed_strips_one_common_prefix():
    t = Trial.from_array(np.arange(18.0).reshape(3, 2, 3), ["Sub:RASI", "Sub:LASI"], rate_hz=100.0)
    t2, warning = t.unprefixed(["RASI", "LASI"])
    assert t2.labels == ("RASI", "LASI") and np.array_equal(t2.xyz, t.xyz)
    assert "'Sub:'" in warning and "2 label(s)" in warning


def test_unprefixed_leaves_other_trials_alone():
    xyz = np.arange(36.0).reshape(3, 4, 3)
    plain = Trial.from_array(xyz[:, :2], ["RASI", "LASI"], rate_hz=100.0)
    assert plain.unprefixed(["RASI", "LASI"]) == (plain, None)                     # nothing to strip
    some = Trial.from_array(xyz[:, :2], ["RASI", "Sub:LASI"], rate_hz=100.0)
    assert some.unprefixed(["RASI", "LASI"]) == (some, None)                       # a model marker is there as it is
    two = Trial.from_array(xyz, ["A:RASI", "A:LASI", "B:RASI", "B:LASI"], rate_hz=100.0)
    assert two.unprefixed(["RASI", "LASI"]) == (two, None)                         # two subjects: no guess
    part = Trial.from_array(xyz[:, :2], ["A:RASI", "B:LASI"], rate_hz=100.0)
    assert part.unprefixed(["RASI", "LASI"]) == (part, None)                       # no one prefix holds them all
    with pytest.raises(InputError, match=r"'A:RASI', 'B:RASI'.*subject prefix"):
        two.require_usable(["RASI", "LASI"])


def test_unprefixed_keeps_a_label_it_would_duplicate():
    t = Trial.from_array(np.arange(27.0).reshape(3, 3, 3), ["Sub:RASI", "Sub:C7", "C7"], rate_hz=100.0)
    t2, warning = t.unprefixed(["RASI"])
    assert t2.labels == ("RASI", "Sub:C7", "C7") and warning


@pytest.mark.parametrize("ext", [".trc", ".c3d"])
def test_fit_reads_prefixed_files(tmp_path, examples, leg, ext):
    path = tmp_path / f"vicon{ext}"
    _prefixed(leg).to_file(path)
    assert Trial.from_file(path).labels[0].startswith(PREFIX)                      # the file keeps the prefix
    res = api.fit(examples / "leg.toml", path)
    first = res.warnings[0]
    assert first["kind"] == "subject_prefix" and repr(PREFIX) in first["message"] and str(path) in first["message"]
    plain = api.fit(examples / "leg.toml", leg.trial)
    for j in plain.joints:
        for m, d in plain.joints[j]["marker_distances"].items():
            assert res.joints[j]["marker_distances"][m] == pytest.approx(d, abs=0.01 if ext == ".c3d" else 1e-6)


def test_cli_fit_json_and_identify_warn(tmp_path, examples, leg, capsys):
    path = tmp_path / "vicon.c3d"
    _prefixed(leg).to_file(path)
    assert main(["fit", str(examples / "leg.toml"), str(path), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["warnings"][0]["kind"] == "subject_prefix"
    assert "subject prefix 'Jane Doe:'" in err
    knee = api.simulate(examples / "knee_21.toml", seed=1, n_frames=60)
    _prefixed(knee).to_file(tmp_path / "knee.trc")
    with pytest.warns(UserWarning, match="subject prefix 'Jane Doe:'"):
        res = api.identify(examples / "knee_21.toml", tmp_path / "knee.trc")
    assert res["knee_r"].n_samples == 60


def test_diagnose_warns(tmp_path, examples):
    sim = api.simulate(examples / "diagnose_leg.toml", seed=2, noise_mm=0.4, n_frames=200)
    path = tmp_path / "vicon.trc"
    _prefixed(sim).to_file(path)
    with pytest.warns(UserWarning, match="subject prefix 'Jane Doe:'"):
        diag = api.diagnose(examples / "diagnose_leg.toml", path, max_steps=0)
    assert set(diag.to_dict()["joints"]) == {"hip", "knee"}


def test_partial_prefix_gives_a_hint(tmp_path, examples, leg):
    path = tmp_path / "mixed.trc"
    _prefixed(leg, keep=("LASI",)).to_file(path)           # LASI as the model names it: nothing is stripped
    with pytest.raises(InputError, match=r"marker 'RASI' \(segment 'pelvis'\) of the model is not in the trial "
                                         r"\(the trial has 'Jane Doe:RASI'"):
        api.fit(examples / "leg.toml", path)
