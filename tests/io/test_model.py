"""Model loading: the examples, the checks on bad files, and the tree ordering."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.errors import InputError
from identcheck.io.model import JOINT_TYPES, Joint, Model, Segment

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

MINIMAL = """
[segments.pelvis]
markers = ["LASI", "RASI", "SACR"]
[segments.thigh_r]
markers = ["RGT", "RTHI", "RKNE"]
[joints.hip_r]
type = "spherical"
parent = "pelvis"
child = "thigh_r"
"""


def write(tmp_path, text, name="model.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def load_error(tmp_path, text) -> InputError:
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        Model.from_toml(path)
    assert str(path) in str(info.value), "the message must name the file"
    return info.value


# ---------------------------------------------------------------------- good files
def test_leg_example():
    model = Model.from_toml(EXAMPLES / "leg.toml")
    assert model.root == "pelvis"
    assert model.joint_order == ("hip_r", "knee_r", "ankle_r")
    assert model.markers == ("LASI", "RASI", "SACR", "RGT", "RTHI", "RKNE", "RTIB", "RANK", "RHEE", "RTOE")
    assert model.marker_segment("RANK") == "shank_r"
    assert model.joints["hip_r"].type == "spherical"
    assert model.joints["knee_r"].type == "revolute"
    assert model.segments["thigh_r"].length_mm == 420.0
    assert model.parent_joint("pelvis") is None
    assert model.parent_joint("foot_r").name == "ankle_r"
    assert [j.name for j in model.child_joints("thigh_r")] == ["knee_r"]
    assert model.joint_markers("knee_r") == (("RGT", "RTHI", "RKNE"), ("RTIB", "RANK"))


def test_knee_21_example_is_the_revolute_2_1_plan():
    model = Model.from_toml(EXAMPLES / "knee_21.toml")
    (joint,) = model.joints.values()
    parent, child = model.joint_markers(joint.name)
    assert (joint.type, len(parent), len(child)) == ("revolute", 2, 1)
    assert model.segments["thigh_r"].positions == {"RTH1": (60.0, -60.0, -250.0), "RTH2": (30.0, -75.0, -320.0)}
    assert joint.axis == (0.0, 1.0, 0.0)
    assert joint.centre_parent == (0.0, 0.0, -400.0)


def test_contract_example_from_dict_and_round_trip():
    import tomllib
    model = Model.from_dict(tomllib.loads(MINIMAL))
    assert model.source == "<dict>"
    assert model.units == "mm"
    again = Model.from_dict(model.to_dict())
    assert again.segments == model.segments and again.joints == model.joints


def test_empty_and_single_marker_segments_are_allowed(tmp_path):
    text = """
[segments.a]
markers = []
[segments.b]
markers = ["M"]
[joints.j]
type = "revolute"
parent = "a"
child = "b"
"""
    model = Model.from_toml(write(tmp_path, text))
    assert model.segments["a"].markers == ()
    assert model.markers == ("M",)


def test_single_segment_without_joints(tmp_path):
    model = Model.from_toml(write(tmp_path, '[segments.only]\nmarkers = ["A", "B"]\n'))
    assert model.root == "only" and model.joint_order == ()


def test_metres_are_converted_to_mm_and_axis_normalised(tmp_path):
    text = 'units = "m"\n' + MINIMAL + """
[segments.pelvis.positions]
LASI = [0.1, 0.2, -0.05]
[segments.shank]
markers = []
[joints.knee]
type = "revolute"
parent = "thigh_r"
child = "shank"
axis = [0, 0, 2]
centre_parent = [0, 0, -0.4]
"""
    model = Model.from_toml(write(tmp_path, text))
    assert model.segments["pelvis"].positions["LASI"] == pytest.approx((100.0, 200.0, -50.0))
    assert model.joints["knee"].axis == (0.0, 0.0, 1.0)
    assert model.joints["knee"].centre_parent == pytest.approx((0.0, 0.0, -400.0))


def test_joint_order_puts_parents_first_even_if_declared_last(tmp_path):
    text = """
[segments.foot]
markers = ["T"]
[segments.shank]
markers = ["S"]
[segments.thigh]
markers = ["K"]
[joints.ankle]
type = "revolute"
parent = "shank"
child = "foot"
[joints.knee]
type = "revolute"
parent = "thigh"
child = "shank"
"""
    model = Model.from_toml(write(tmp_path, text))
    assert model.root == "thigh"
    assert model.joint_order == ("knee", "ankle")
    assert model.markers == ("T", "S", "K")  # file order, not tree order


# ---------------------------------------------------------------------- bad files
def test_file_not_found(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(InputError, match=r"nope\.toml: file not found"):
        Model.from_toml(missing)


def test_toml_syntax_error_names_the_line(tmp_path):
    err = load_error(tmp_path, '[segments.pelvis]\nmarkers = ["A",\ntype = = 3\n')
    assert "TOML syntax error" in str(err)
    assert "line 3" in str(err)


def test_unknown_segment_in_joint(tmp_path):
    err = load_error(tmp_path, MINIMAL.replace('child = "thigh_r"', 'child = "thigh"'))
    assert "joints.hip_r.child: unknown segment 'thigh'" in str(err)
    assert "did you mean 'thigh_r'" in str(err)
    assert "more than one root" not in str(err), "a bad joint must not also be reported as a disconnection"


def test_unknown_joint_type_lists_allowed(tmp_path):
    err = load_error(tmp_path, MINIMAL.replace('"spherical"', '"hinge"'))
    assert "joints.hip_r.type: unknown joint type 'hinge'" in str(err)
    assert "allowed: " + ", ".join(JOINT_TYPES) in str(err)
    assert len(err.problems) == 1


@pytest.mark.parametrize("spelled", ["Spherical", "SPHERICAL", " spherical "])
def test_a_joint_type_in_any_case_is_the_type(tmp_path, spelled):
    """The model takes a joint type in any case, as ``identcheck rank`` and ``table`` do (``rank Revolute 2 1``
    ran while ``type = "Revolute"`` in a model was refused), and stores it lower case."""
    model = Model.from_toml(write(tmp_path, MINIMAL.replace('"spherical"', f'"{spelled}"')))
    assert model.joints["hip_r"].type == "spherical"
    assert Model.from_dict(model.to_dict()).joints["hip_r"].type == "spherical"


def test_duplicate_marker_names_both_segments(tmp_path):
    err = load_error(tmp_path, MINIMAL.replace('"RGT", "RTHI"', '"RASI", "RTHI"'))
    assert "duplicate marker 'RASI'" in str(err)
    assert "segments.pelvis.markers" in str(err) and "segments.thigh_r.markers" in str(err)


def test_marker_twice_in_one_segment(tmp_path):
    err = load_error(tmp_path, MINIMAL.replace('"RGT", "RTHI", "RKNE"', '"RGT", "RGT"'))
    assert "listed twice in segments.thigh_r.markers" in str(err)


def test_cycle(tmp_path):
    text = MINIMAL + """
[segments.shank]
markers = []
[joints.knee]
type = "revolute"
parent = "thigh_r"
child = "shank"
[joints.loop]
type = "revolute"
parent = "shank"
child = "thigh_r"
"""
    err = load_error(tmp_path, text)
    assert "cycle" in str(err)
    assert "thigh_r -> shank -> thigh_r" in str(err) or "shank -> thigh_r -> shank" in str(err)


def test_pure_cycle_without_root(tmp_path):
    text = """
[segments.a]
markers = []
[segments.b]
markers = []
[joints.ab]
type = "revolute"
parent = "a"
child = "b"
[joints.ba]
type = "revolute"
parent = "b"
child = "a"
"""
    err = load_error(tmp_path, text)
    assert "joints form a cycle" in str(err) and "joints.ab" in str(err) and "joints.ba" in str(err)


def test_segment_with_two_parents(tmp_path):
    text = MINIMAL + """
[segments.other]
markers = []
[joints.extra]
type = "spherical"
parent = "other"
child = "thigh_r"
"""
    err = load_error(tmp_path, text)
    assert ("segment 'thigh_r' has two parents: joints.hip_r (parent 'pelvis') "
            "and joints.extra (parent 'other')") in str(err)


def test_disconnected_segments(tmp_path):
    err = load_error(tmp_path, MINIMAL + '[segments.arm]\nmarkers = ["X"]\n')
    assert "more than one root segment" in str(err)
    assert "pelvis, arm" in str(err)


def test_missing_keys(tmp_path):
    text = """
[segments.pelvis]
[segments.thigh]
markers = []
[joints.hip]
parent = "pelvis"
"""
    err = load_error(tmp_path, text)
    msg = str(err)
    assert "segments.pelvis.markers: missing" in msg
    assert "joints.hip.type: missing" in msg
    assert "joints.hip.child: missing" in msg


def test_no_segments(tmp_path):
    err = load_error(tmp_path, 'units = "mm"\n')
    assert "segments: missing" in str(err)


def test_wrong_value_types(tmp_path):
    text = """
units = "inch"
[segments.pelvis]
markers = "LASI"
length_mm = -3
[segments.thigh]
markers = ["A"]
[segments.thigh.positions]
A = [1, 2]
[joints.hip]
type = 3
parent = "pelvis"
child = "thigh"
"""
    err = load_error(tmp_path, text)
    msg = str(err)
    assert "units: 'inch' is not a known unit" in msg
    assert "segments.pelvis.markers: expected a list of non-empty marker names" in msg
    assert "segments.pelvis.length_mm: expected a positive number" in msg
    assert "segments.thigh.positions.A: expected 3 finite numbers" in msg
    assert "joints.hip.type: expected a string" in msg
    assert f"{len(err.problems)} problems" in msg and len(err.problems) == 5


def test_all_problems_reported_at_once(tmp_path):
    text = MINIMAL.replace('"spherical"', '"ball"').replace('"RGT", "RTHI"', '"LASI", "RTHI"')
    text += '[segments.arm]\nmarkers = []\n'
    err = load_error(tmp_path, text)
    assert len(err.problems) == 3
    assert "3 problems" in str(err)


def test_unknown_key_suggests_the_right_one(tmp_path):
    err = load_error(tmp_path, MINIMAL.replace("parent =", "parnet ="))
    assert "joints.hip_r.parnet: unknown key" in str(err)
    assert "did you mean 'parent'" in str(err)
    assert "joints.hip_r.parent: missing" in str(err)


def test_positions_must_name_listed_markers_and_differ(tmp_path):
    text = MINIMAL + """
[segments.thigh_r.positions]
RGT = [0, 80, -60]
RTHI = [0, 80, -60]
RXX = [1, 2, 3]
"""
    err = load_error(tmp_path, text)
    assert "segments.thigh_r.positions.RXX: marker not listed in segments.thigh_r.markers" in str(err)
    assert "markers 'RGT' and 'RTHI' are at the same position" in str(err)


def test_axis_only_for_revolute_and_not_zero(tmp_path):
    err = load_error(tmp_path, MINIMAL + "axis = [0, 0, 0]\n")
    assert "joints.hip_r.axis: must not be the zero vector" in str(err)
    assert "joints.hip_r.axis: only a revolute joint has a hinge axis" in str(err)


def test_self_joint(tmp_path):
    err = load_error(tmp_path, MINIMAL.replace('child = "thigh_r"', 'child = "pelvis"'))
    assert "joints.hip_r: parent and child are the same segment 'pelvis'" in str(err)


def test_direct_construction_is_checked_too():
    model = Model.from_dict({"segments": {"a": {"markers": ["M"]}, "b": {"markers": []}},
                             "joints": {"j": {"type": "revolute", "parent": "a", "child": "b"}}})
    loop = dict(model.joints, k=Joint("k", "revolute", "b", "a"))
    with pytest.raises(InputError, match="cycle"):
        dataclasses.replace(model, joints=loop)
    dup = dict(model.segments, b=Segment("b", ("M",)))
    with pytest.raises(InputError, match="duplicate marker 'M'"):
        dataclasses.replace(model, segments=dup)


def test_marker_segment_unknown_marker():
    model = Model.from_toml(EXAMPLES / "leg.toml")
    with pytest.raises(InputError, match=r"leg\.toml: unknown marker 'RKNEE'.*did you mean 'RKNE'"):
        model.marker_segment("RKNEE")


# ---------------------------------------------------------------------- random trees
@st.composite
def tree_dicts(draw):
    n = draw(st.integers(1, 7))
    names = [f"s{i}" for i in range(n)]
    parents = [draw(st.integers(0, i - 1)) for i in range(1, n)]
    order = draw(st.permutations(range(1, n)))  # joints declared in any order
    segments = {name: {"markers": [f"{name}m{k}" for k in range(draw(st.integers(0, 3)))]}
                for name in draw(st.permutations(names))}
    joints = {f"j{i}": {"type": draw(st.sampled_from(JOINT_TYPES)), "parent": names[parents[i - 1]],
                        "child": names[i]} for i in order}
    return segments, joints


@settings(max_examples=60, deadline=None)
@given(tree_dicts())
def test_random_trees_order_parents_before_children(tree):
    segments, joints = tree
    model = Model.from_dict({"segments": segments, "joints": joints})
    assert model.root == "s0"
    assert sorted(model.joint_order) == sorted(joints)
    placed = {model.root}
    for name in model.joint_order:
        assert model.joints[name].parent in placed
        placed.add(model.joints[name].child)
    assert placed == set(segments)
    assert model.markers == tuple(m for s in segments.values() for m in s["markers"])
    for seg, table in segments.items():
        for m in table["markers"]:
            assert model.marker_segment(m) == seg


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(["leg_length_mm", "right_leg_length_mm", "left_leg_length_mm", "marker_diameter_mm"]),
       st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6), st.text(max_size=5),
                 st.booleans()))
def test_subject_values_are_plausible_mm_or_an_error_naming_the_key(key, value):
    """[subject]: a value inside its range (mm) is kept as a float and survives to_dict/from_dict; anything else
    (a leg length in metres, a negative, NaN, text, a boolean) is an error naming ``subject.KEY``."""
    lo, hi = {"marker_diameter_mm": (2, 40)}.get(key, (300, 1500))
    d = {"segments": {"a": {"markers": ["x"]}}, "subject": {key: value}}
    ok = not isinstance(value, (bool, str)) and value == value and lo <= value <= hi
    if ok:
        m = Model.from_dict(d)
        assert m.subject == {key: float(value)} and Model.from_dict(m.to_dict()).subject == m.subject
    else:
        with pytest.raises(InputError) as e:
            Model.from_dict(d)
        assert f"subject.{key}" in str(e.value)


def test_subject_unknown_key_and_both_leg_spellings_are_errors():
    with pytest.raises(InputError) as e:
        Model.from_dict({"segments": {"a": {"markers": ["x"]}},
                         "subject": {"leg_lenght_mm": 900, "leg_length_mm": 900, "right_leg_length_mm": 880}})
    text = str(e.value)
    assert "subject.leg_lenght_mm: unknown key" in text and "leg_length_mm" in text and "not both" in text


@pytest.mark.parametrize("line, key", [
    ("length_mm = 1e300", "segments.pelvis.length_mm"),
    ("positions.LASI = [0.0, 2e5, 0.0]", "segments.pelvis.positions.LASI"),
])
def test_lengths_and_positions_beyond_100_m_are_refused(tmp_path, line, key):
    """A length or position beyond 100 m is a typo or a unit mistake: refused naming its key (1e300 mm had
    overflowed in simulate, which then blamed the samples)."""
    err = load_error(tmp_path, MINIMAL.replace('markers = ["LASI", "RASI", "SACR"]',
                                               f'markers = ["LASI", "RASI", "SACR"]\n{line}'))
    assert key in str(err) and ("100 m" in str(err) or "100000" in str(err))


def test_an_axis_is_a_direction_of_any_length(tmp_path):
    model = Model.from_toml(write(tmp_path, MINIMAL.replace('"spherical"', '"revolute"\naxis = [0.0, 0.0, 1e9]')))
    assert model.joints["hip_r"].axis == (0.0, 0.0, 1.0)


@given(name=st.text(st.characters(whitelist_categories=("Lu", "Ll", "Nd")), min_size=1, max_size=8),
       before=st.sampled_from(["", " ", "\t"]), after=st.sampled_from(["", " ", "  ", "\t"]))
def test_a_marker_name_with_spaces_at_its_ends_is_refused_naming_it(name, before, after):
    """Labels read from C3D and TRC files lose the spaces at their ends, so a model name keeping them could never be
    found in a trial: it is refused by its segment's field, with the name to write instead."""
    name = "Q" + name          # not one of the other markers' names
    padded = before + name + after
    d = {"segments": {"pelvis": {"markers": ["A", "B", padded]}, "thigh": {"markers": ["C"]}},
         "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"}}}
    if padded == name:
        assert name in Model.from_dict(d).markers
        return
    with pytest.raises(InputError) as err:
        Model.from_dict(d)
    assert "segments.pelvis.markers" in str(err.value) and repr(name) in str(err.value)


@settings(max_examples=80, deadline=None)
@given(data=st.data())
def test_below_a_root_nothing_poses_is_a_subtree_whose_root_is_posed(data):
    """Random trees with a markerless root: :meth:`Model.below_root` keeps a whole subtree of the model whose root is
    posed (a marker, three joint points, or no joint below it), and leaves out every other joint, each under a left-out
    joint that maps to itself; a root with a marker, or lent three points, is kept as it is. A subtree holding joints
    is preferred to a leaf: a seven-marker leaf had been kept over a fully marked hinge beside it."""
    n = data.draw(st.integers(2, 7))
    parents = [None] + [data.draw(st.integers(0, k - 1)) for k in range(1, n)]
    counts = [0] + [data.draw(st.integers(0, 7)) for _ in range(n - 1)]
    types = [data.draw(st.sampled_from(["spherical", "revolute"])) for _ in range(n)]
    model = Model.from_dict({
        "units": "mm", "segments": {f"s{k}": {"markers": [f"m{k}_{i}" for i in range(counts[k])]} for k in range(n)},
        "joints": {f"j{k}": {"type": types[k], "parent": f"s{parents[k]}", "child": f"s{k}"} for k in range(1, n)}})
    below, gone = model.below_root()
    if model.joint_points("s0") >= 3:
        assert below is model and gone == {}
        return
    assert set(below.segments) == model.segments_below(below.root)
    assert bool(below.segments[below.root].markers) or below.joint_points(below.root) >= 3 or not below.joints
    assert set(below.joints) | set(gone) == set(model.joints) and not set(below.joints) & set(gone)
    assert all(gone[above] == above for above in gone.values())


def test_below_a_root_nothing_poses_a_subtree_with_joints_is_kept_over_a_leaf():
    """A markerless pelvis with a seven-marker leaf on one ball joint and a 3 | 3 hinge below the other: the hinge's
    subtree is kept (the leaf, more markers but no joint, had been); and a chain of two markerless segments is left
    out whole, down to the first posed one."""
    forked = Model.from_dict({"units": "mm", "segments": {
        "P": {"markers": []}, "T": {"markers": [f"t{i}" for i in range(7)]}, "A": {"markers": ["a1", "a2", "a3"]},
        "B": {"markers": ["b1", "b2", "b3"]}}, "joints": {
        "jt": {"type": "spherical", "parent": "P", "child": "T"},
        "ja": {"type": "spherical", "parent": "P", "child": "A"},
        "jb": {"type": "revolute", "parent": "A", "child": "B"}}})
    below, gone = forked.below_root()
    assert below.root == "A" and set(below.joints) == {"jb"} and gone == {"jt": "jt", "ja": "ja"}
    chain = Model.from_dict({"units": "mm", "segments": {
        "A": {"markers": []}, "B": {"markers": []}, "C": {"markers": ["c1", "c2", "c3"]},
        "D": {"markers": ["d1", "d2", "d3"]}}, "joints": {
        "j1": {"type": "spherical", "parent": "A", "child": "B"},
        "j2": {"type": "spherical", "parent": "B", "child": "C"},
        "j3": {"type": "revolute", "parent": "C", "child": "D"}}})
    below, gone = chain.below_root()
    assert below.root == "C" and set(below.joints) == {"j3"} and gone == {"j1": "j1", "j2": "j2"}
