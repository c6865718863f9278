"""``identcheck skeleton`` on measured trials (/work/shared/data/real, see its README): the inferred segments and
trees against the hand-written models in examples/.

Walking moves the hips and knees mostly about one axis and hardly moves the trunk against the pelvis, so the
checks are the anatomy the motion can show: the leg clusters are found as segments, the hips join the thighs to
the pelvis and the knees the shanks to the thighs, and, given the example models' segments, the tree and the joint
types are the examples' own (hips spherical, knees revolute). The functional trials (one joint moving, the rest of
the body still) are checked with their clusters given (the knee is a hinge, the hip a ball joint) and alone (the
leg's clusters chain pelvis - thigh - shank).
"""
import json
from pathlib import Path

import pytest

from identcheck import cli
from identcheck.api import skeleton
from identcheck.io.model import Model

ROOT = Path(__file__).resolve().parents[2]
EX = ROOT / "examples"
DATA = Path("/work/shared/data/real")
WALK, WALK2 = DATA / "opensim_subject01_walk1.trc", DATA / "opensim_walking2.c3d"
HIP, KNEE = DATA / "biobuddy_right_hip.c3d", DATA / "biobuddy_right_knee.c3d"

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not all(p.exists() for p in (WALK, WALK2, HIP, KNEE)),
                                                   reason="real trials not available in /work/shared/data/real")]


def named(doc: dict, model: Model) -> set:
    """The result's joints as (parent, child) pairs of the model's segment names (each result segment named by the
    model segment holding its first marker)."""
    owner = {m: s for s, seg in model.segments.items() for m in seg.markers}
    name = {g: owner.get(ms[0], g) for g, ms in doc["segments"].items()}
    return {(name[j["parent"]], name[j["child"]]) for j in doc["joints"]}


def test_walk_trial_alone_gives_the_leg_segments_and_joints():
    """subject01_walk1 (OpenSim, 41 markers, one stride): the pelvis, thigh and shank clusters of both legs, the
    trunk and the head come out as segments; hips and knees join them as in examples/real_walk_leg.toml (both
    legs); the knees are hinges. Each arm hangs from the trunk through its upper arm, which carries one marker
    (the biceps): trunk - upper arm - forearm, not the two forearms joined to each other (they swing together)."""
    pytest.importorskip("scipy")
    doc = skeleton(WALK).to_dict()
    groups = {frozenset(ms) for ms in doc["segments"].values()}
    clusters = [["R.ASIS", "L.ASIS", "V.Sacral"], ["Sternum", "R.Acromium", "L.Acromium"],
                ["R.Temple", "L.Temple", "Top.Head"]] + [
        [f"{s}.{part}.{where}" for where in ("Upper", "Front", "Rear")] for s in "RL" for part in ("Thigh", "Shank")]
    assert all(frozenset(c) in groups for c in clusters)
    owner = {m: s for s, ms in doc["segments"].items() for m in ms}
    seg = {k: owner[m] for k, m in {"pelvis": "R.ASIS", "thigh_r": "R.Thigh.Upper", "shank_r": "R.Shank.Upper",
                                    "thigh_l": "L.Thigh.Upper", "shank_l": "L.Shank.Upper"}.items()}
    joints = {(j["parent"], j["child"]): j for j in doc["joints"]}
    for p, c in (("pelvis", "thigh_r"), ("pelvis", "thigh_l"), ("thigh_r", "shank_r"), ("thigh_l", "shank_l")):
        assert (seg[p], seg[c]) in joints
    assert joints[seg["thigh_r"], seg["shank_r"]]["type"] == "revolute"
    assert joints[seg["thigh_l"], seg["shank_l"]]["type"] == "revolute"
    assert doc["root"] == seg["pelvis"] and doc["playback"]["rms_mm"] < 20
    pairs = {frozenset(p) for p in joints}
    for side in "RL":
        trunk, upper, fore = owner["Sternum"], owner[f"{side}.Bicep"], owner[f"{side}.Elbow"]
        assert doc["segments"][upper] == [f"{side}.Bicep"]
        assert frozenset((trunk, upper)) in pairs and frozenset((upper, fore)) in pairs
        ev = joints.get((trunk, upper), joints.get((upper, trunk)))["evidence"]["tree"]
        assert ev["runner_up"]["replaced"] and set(ev["runner_up"]["between"]) == {trunk, fore}
        assert ev["inserted"].startswith(f"{upper} put between ")
    assert frozenset((owner["R.Elbow"], owner["L.Elbow"])) not in pairs


def test_walking2_with_the_example_segments_gives_the_example_model(tmp_path, capsys):
    """opensim_walking2 (Vicon, gaps) with the segments of examples/real_walking2_legs.toml: the tree and every
    joint type are the example's."""
    example = Model.from_toml(EX / "real_walking2_legs.toml")
    rc = cli.main(["skeleton", str(WALK2), "--segments", str(EX / "real_walking2_legs.toml"), "--out",
                   str(tmp_path / "m.toml"), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert rc in (0, 1)
    got = {(j["parent"], j["child"], j["type"]) for j in doc["joints"]}
    assert got == {(j.parent, j.child, j.type) for j in example.joints.values()}


def test_walking2_alone_gives_anatomically_sensible_legs():
    """Without the segments: pelvis, right thigh and right shank clusters are found and chained hip - knee; the
    left thigh's markers join the left shank to the pelvis (a two-marker thigh is put between them, or the thigh
    cluster is posed), never a pelvis-shank joint."""
    doc = skeleton(WALK2).to_dict()
    owner = {m: s for s, ms in doc["segments"].items() for m in ms}
    pelvis, thigh_r, shank_r = owner["RASI"], owner["RTH1"], owner["RTB1"]
    assert {"RTH1", "RTH2", "RTH3"} <= set(doc["segments"][thigh_r])
    assert {"RTB1", "RTB2", "RTB3"} <= set(doc["segments"][shank_r])
    parent = {j["child"]: j["parent"] for j in doc["joints"]}
    assert parent[thigh_r] == pelvis and parent[shank_r] == thigh_r
    shank_l = owner["LTB1"]
    assert parent[shank_l] == owner["LTH1"] and parent[owner["LTH1"]] == pelvis


def test_walking2_alone_gives_every_leg_segment_and_joint():
    """Every segment of the lower body comes out whole (the pelvis's skin markers and a thigh marker wobble 6-8 mm,
    more than the trial-wide tolerance, but far less than against any other segment), chained pelvis - thigh -
    shank - foot on both sides, hips ball joints, knees hinges."""
    doc = skeleton(WALK2).to_dict()
    whole = {"pelvis": {"LPSI", "RPSI", "RASI", "LASI"}, "thigh_r": {"RTH1", "RTH2", "RTH3"},
             "thigh_l": {"LTH1", "LTH2", "LTH3"}, "shank_r": {"RTB1", "RTB2", "RTB3"},
             "shank_l": {"LTB1", "LTB2", "LTB3"},
             "foot_r": {"RCAL", "RMT1", "RMT2"}, "foot_l": {"LCAL", "LMT1", "LMT2"}}
    owner = {m: s for s, ms in doc["segments"].items() for m in ms}
    seg = {}
    for name, markers in whole.items():
        (seg[name],) = {owner[m] for m in markers}
    assert len(set(seg.values())) == len(seg)
    joints = {(j["parent"], j["child"]): j["type"] for j in doc["joints"]}
    for side in "rl":
        assert joints[seg["pelvis"], seg[f"thigh_{side}"]] == "spherical"
        assert joints[seg[f"thigh_{side}"], seg[f"shank_{side}"]] == "revolute"
        assert (seg[f"shank_{side}"], seg[f"foot_{side}"]) in joints


@pytest.mark.parametrize("trial, hip_type, knee_type", [(HIP, "spherical", None), (KNEE, None, "revolute")])
def test_functional_trials_alone_give_pelvis_thigh_shank(trial, hip_type, knee_type):
    """biobuddy's functional trials, full-body marker set, no segments given: the still body sets a rigidity
    tolerance of 1-3 mm that the moving leg's skin markers exceed (3-9 mm), yet the right thigh and shank clusters
    come out whole and chain pelvis - thigh - shank; the joint that moves is typed (the hip a ball joint, the knee a
    hinge). The groups held together beyond the tolerance are reported, so the skeleton is not called settled."""
    pytest.importorskip("ezc3d")
    doc = skeleton(trial).to_dict()
    owner = {m: s for s, ms in doc["segments"].items() for m in ms}
    (thigh,) = {owner[m] for m in ("RTHI1", "RTHI2", "RTHI3")}
    (shank,) = {owner[m] for m in ("RLEG1", "RLEG2", "RLEG3")}
    pelvis = [owner[m] for m in ("LPSIS", "RPSIS", "LASIS", "RASIS") if m in owner]
    assert len(pelvis) >= 3 and len(set(pelvis)) == 1
    joints = {(j["parent"], j["child"]): j["type"] for j in doc["joints"]}
    assert (pelvis[0], thigh) in joints and (thigh, shank) in joints
    assert hip_type is None or joints[pelvis[0], thigh] == hip_type
    assert knee_type is None or joints[thigh, shank] == knee_type
    assert doc["grouping"]["widened"] and not doc["ok"]


def test_a_static_trial_is_refused(tmp_path, capsys):
    """biobuddy's anatomical pose (no pair of markers changes its distance by more than 5.3 mm) is refused as
    static, naming the file, and no model is written."""
    trial = DATA / "biobuddy_anat_pose_ECH.c3d"
    pytest.importorskip("ezc3d")
    rc = cli.main(["skeleton", str(trial), "--out", str(tmp_path / "m.toml")])
    err = capsys.readouterr().err
    assert rc == 2 and trial.name in err and "the trial is static" in err and not (tmp_path / "m.toml").exists()


@pytest.mark.parametrize("trial, example, kind", [(KNEE, "real_right_knee_cluster.toml", "revolute"),
                                                  (HIP, "real_right_hip_cluster.toml", "spherical")])
def test_functional_trials_type_their_joint(trial, example, kind):
    """biobuddy's knee flexion trial gives a hinge, its hip star-arc trial a ball joint (clusters as in the examples)."""
    pytest.importorskip("ezc3d")
    doc = skeleton(trial, segments=EX / example).to_dict()
    (j,) = doc["joints"]
    assert j["type"] == kind and j["confidence"] > 0.8 and doc["ok"]
    assert (j["parent"], j["child"]) == next((v.parent, v.child) for v in Model.from_toml(EX / example).joints.values())


def test_fit_accepts_the_model_inferred_from_a_real_trial(tmp_path, capsys):
    """The model written from subject01_walk1 with the segments of examples/real_walk_leg.toml runs through fit."""
    out = tmp_path / "walk.toml"
    assert cli.main(["skeleton", str(WALK), "--segments", str(EX / "real_walk_leg.toml"), "--out", str(out)]) in (0, 1)
    capsys.readouterr()
    rc = cli.main(["fit", str(out), str(WALK), "--json"])
    fitted = json.loads(capsys.readouterr().out)
    assert rc in (0, 1) and set(fitted["joints"]) == set(Model.from_toml(out).joints)
