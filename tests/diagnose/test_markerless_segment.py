"""A model segment without markers that no joint points pose (a foot without markers): ``diagnose`` leaves the joint
above it, and everything below, out as ``fit`` does, diagnoses the rest, reports the joints left out as undetermined
with why, and says so on standard error. It had refused the whole model (exit 2), the documentation's own example
among them, where ``fit`` answered for the hip and knee."""
from __future__ import annotations

import json

import numpy as np
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


def test_a_markerless_root_with_nothing_below_it_to_fit_is_named_as_the_models(tmp_path, capsys):
    """A root without markers whose one joint is all the model has: nothing is left once it is left out, so the model
    is refused (exit 2) by the root's field, saying what to do."""
    model = tmp_path / "bare_root.toml"
    model.write_text('units = "mm"\n[segments.pelvis]\nmarkers = []\n[segments.thigh]\nmarkers = ["A", "B", "C"]\n'
                     '[joints.hip]\ntype = "spherical"\nparent = "pelvis"\nchild = "thigh"\n')
    trial = tmp_path / "t.c3d"
    assert cli.main(["simulate", str(model), "--out", str(trial), "--frames", "200", "--noise-mm", "0.3"]) == 0
    capsys.readouterr()
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) == 2
    err = capsys.readouterr().err
    assert "bare_root.toml" in err and "segments.pelvis.markers" in err and "Traceback" not in err


KNEE_BELOW_A_BARE_ROOT = """units = "mm"
[segments.s0]
markers = []
[segments.s1]
markers = ["B1", "B2", "B3"]
[segments.s2]
markers = ["C1", "C2", "C3"]
[segments.s3]
markers = ["D1"]
[joints.j1]
type = "spherical"
parent = "s0"
child = "s1"
[joints.j2]
type = "revolute"
parent = "s1"
child = "s2"
[joints.j3]
type = "spherical"
parent = "s0"
child = "s3"
"""


def test_a_knee_below_a_markerless_root_is_fitted_and_diagnosed(tmp_path):
    """s0[] -ball- s1[3] -hinge- s2[3], and s0 -ball- s3[1]: nothing poses the root, and every joint had been
    undetermined, the fully marked hinge among them (an independent check found 28 such joints). ``fit`` and
    ``diagnose`` leave the root's joints out, saying why, and fit the subtree with the most markers: the hinge is
    determined by both, with the same distances within its interval."""
    import identcheck as ic

    path = tmp_path / "bare_root.toml"
    path.write_text(KNEE_BELOW_A_BARE_ROOT)
    sim = ic.simulate(path, n_frames=400, noise_mm=0.4, seed=3)
    fitted = ic.fit(path, sim.trial).to_dict()["joints"]
    diag = ic.diagnose(path, sim.trial).to_dict()["joints"]
    for joints in (fitted, diag):
        assert joints["j2"]["practical"]["verdict"] == "determined"
        for j in ("j1", "j3"):
            assert joints[j]["practical"]["verdict"] == "undetermined"
            why = joints[j]["practical"]["reason"]    # (fit's: the case its markers meet is not identifiable at all)
            assert "has no marker and its joints lend" in why or (
                joints is fitted and why.startswith("not identifiable")), why
    for m, (lo, hi) in fitted["j2"]["marker_distances_ci95"].items():
        assert lo - 0.05 <= diag["j2"]["marker_distances"][m] <= hi + 0.05, m


def test_a_static_trial_stays_a_degenerate_answer(tmp_path, capsys, examples):
    """A static trial of the bundled knee (its first pose held, with noise): the hinge never turns, so nothing is
    left to diagnose once it is left out; the answer is the degenerate one (exit 1, ``{"ok": false, "degenerate":
    ...}`` naming the trial), as before segments nothing poses were left out, not a refusal of the model (exit 2)."""
    from identcheck.io.trc import write_trc
    from identcheck.simulate.rigid import simulate
    from identcheck.io.model import Model

    model = examples / "knee_21.toml"
    sim = simulate(Model.from_toml(model), n_frames=200, noise_mm=0.0, seed=1)
    still = np.repeat(sim.trial.as_array()[:1], 200, axis=0) + np.random.default_rng(1).normal(0, 0.3, (200, 3, 3))
    trial = tmp_path / "still.trc"
    write_trc(trial, still, sim.trial.labels, sim.trial.rate_hz)
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) == 1
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert doc["ok"] is False and "still.trc" in doc["degenerate"] and "Traceback" not in out.err


def test_a_markerless_shank_between_two_hinges_is_left_out_as_fit_leaves_it(tmp_path, capsys, examples):
    """The bundled leg with its shank's markers taken off: the knee and ankle hinges beside it would lend four points,
    but neither can be placed without the shank's markers (``fit`` calls both not identifiable). ``diagnose`` leaves
    the knee and what hangs below out and diagnoses the hip, as ``fit`` answers it, where it had stopped on
    degenerate data naming the trial (exit 1)."""
    model = tmp_path / "leg_bare_shank.toml"
    text = (examples / "leg.toml").read_text().replace('markers = ["RTIB", "RANK"]', "markers = []")
    assert text != (examples / "leg.toml").read_text()
    model.write_text(text)
    trial = tmp_path / "full.c3d"
    assert cli.main(["simulate", str(examples / "leg.toml"), "--out", str(trial), "--frames", "300", "--noise-mm",
                     "0.5", "--seed", "4"]) == 0
    capsys.readouterr()
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) in (0, 1)
    doc = json.loads(capsys.readouterr().out)
    assert "degenerate" not in doc
    for joint in ("knee_r", "ankle_r"):
        assert doc["joints"][joint]["practical"]["verdict"] == "undetermined"
        assert doc["joints"][joint]["practical"]["reason"].startswith("left out")
    assert "segments.shank_r.markers: none" in doc["joints"]["knee_r"]["practical"]["reason"]
    assert doc["joints"]["hip_r"]["practical"]["verdict"] == "determined"


@pytest.mark.parametrize("seed", [1, 6])
def test_a_joint_no_motion_identifies_is_left_out_with_what_hangs_below_and_the_rest_diagnosed(tmp_path, capsys,
                                                                                               examples, seed):
    """One marker on each segment below a three-marker pelvis, every joint a ball: the knee is spherical (2,1) on the
    hip centre and the thigh's marker, which no motion identifies (``fit`` says so); ``diagnose`` had stopped on
    degenerate data, blaming the trial for a segment no points pose. It leaves the knee and the ankle below it out
    with ``fit``'s reason and diagnoses the hip."""
    model = tmp_path / "chain_of_ones.toml"
    model.write_text('units = "mm"\n[segments.pelvis]\nmarkers = ["LASI", "RASI", "SACR"]\n'
                     '[segments.thigh_r]\nmarkers = ["RKNE"]\n[segments.shank_r]\nmarkers = ["RANK"]\n'
                     '[segments.foot_r]\nmarkers = ["RTOE"]\n'
                     + "".join(f'[joints.{j}]\ntype = "spherical"\nparent = "{p}"\nchild = "{c}"\n' for j, p, c in [
                         ("hip_r", "pelvis", "thigh_r"), ("knee_r", "thigh_r", "shank_r"),
                         ("ankle_r", "shank_r", "foot_r")]))
    trial = tmp_path / "leg.trc"
    assert cli.main(["simulate", str(examples / "leg.toml"), "--out", str(trial), "--frames", "300",
                     "--noise-mm", "0.5", "--seed", str(seed)]) == 0
    capsys.readouterr()
    assert cli.main(["fit", str(model), str(trial), "--json"]) in (0, 1)
    fitted = json.loads(capsys.readouterr().out)["joints"]
    assert not fitted["knee_r"]["identifiable"] and "not identifiable" in fitted["knee_r"]["excitation"]["reason"]
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) in (0, 1)
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert "degenerate" not in doc and "knee_r left out" in out.err
    knee, ankle = doc["joints"]["knee_r"], doc["joints"]["ankle_r"]
    assert knee["practical"]["reason"] == "left out: " + fitted["knee_r"]["excitation"]["reason"]
    assert ankle["practical"]["verdict"] == "undetermined" and "hangs below knee_r" in ankle["practical"]["reason"]
    assert doc["joints"]["hip_r"]["marker_distances"].keys() == fitted["hip_r"]["marker_distances"].keys()


@pytest.mark.parametrize("marker, joint", [("RTIB", "knee_r"), ("RHEE", "ankle_r")])
def test_a_segment_seen_in_too_few_frames_is_left_out_as_fit_leaves_it(tmp_path, capsys, examples, marker, joint):
    """One shank (foot) marker seen in a single frame: no start poses the segment. ``fit`` leaves the joint above it
    and what hangs below out of its whole-tree fit and answers the rest; ``diagnose`` had stopped on degenerate data
    for the whole model. It now leaves the same joints out, naming the marker, and diagnoses the rest."""
    from identcheck.io.trc import read_trc, write_trc

    trial = tmp_path / "leg.trc"
    assert cli.main(["simulate", str(examples / "leg.toml"), "--out", str(trial), "--frames", "200",
                     "--noise-mm", "0.5", "--seed", "3"]) == 0
    data = read_trc(trial)
    xyz = data.xyz.copy()
    xyz[1:, data.labels.index(marker)] = np.nan
    rare = tmp_path / "rare.trc"
    write_trc(rare, xyz, data.labels, data.rate_hz)
    capsys.readouterr()
    assert cli.main(["fit", str(examples / "leg.toml"), str(rare), "--json"]) == 1
    fitted = json.loads(capsys.readouterr().out)["joints"]
    assert cli.main(["diagnose", str(examples / "leg.toml"), str(rare), "--json"]) in (0, 1)
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert "degenerate" not in doc and f"{joint} left out" in out.err
    below = ["knee_r", "ankle_r"][["knee_r", "ankle_r"].index(joint):]
    for j in doc["joints"]:
        verdict = doc["joints"][j]["practical"]["verdict"]
        if j in below:
            assert verdict == "undetermined" and fitted[j]["practical"]["verdict"] == "undetermined"
            assert "left out" in doc["joints"][j]["practical"]["reason"] and marker in doc["joints"][j]["practical"][
                "reason"]
        else:
            assert doc["joints"][j]["marker_distances"], j
