"""Markers that move with both segments of a joint (identcheck.infer.joint_markers): a marker on a hinge's axis
keeps its place in both segments' frames however far the joint turns, so its segment is a choice; markers off the
axis turn with their own segment."""
import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.infer.joint_markers import markers_on_joints

F = 500
T = np.arange(F) / 100.0


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**16), st.floats(40.0, 100.0), st.floats(0.05, 0.8), st.floats(0.0, 4.0))
def test_a_marker_on_a_hinge_axis_moves_with_both_segments(seed, range_deg, sigma, wobble):
    """A hinge turning `range_deg`; the parent carries four markers and the child three, all 120-250 mm off the
    axis line, and the child one more on the axis (with skin wobble up to 4 mm): that one, and only that one, is
    reported."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(range_deg) / 2 * np.sin(2 * np.pi * rng.uniform(0.3, 0.8) * T)
    turn = Rotation.from_rotvec(angle[:, None] * axis).as_matrix()
    centre = np.array([0.0, 0.0, 900.0])
    def off_axis(n, around):
        """n points near `around` (relative to the centre), 120-250 mm from the axis line."""
        out = []
        while len(out) < n:
            p = rng.uniform(-150, 150, size=3) + around
            if 120 <= np.linalg.norm(p - p @ axis * axis) <= 250:
                out.append(p)
        return out

    parent = np.array(off_axis(4, [0, 0, 250])) + centre
    off = off_axis(3, [0, 0, -180])
    on_axis = 50.0 * axis
    child_local = np.vstack(off + [on_axis])
    child = np.einsum("fij,nj->fni", turn, child_local) + centre
    child[:, 3] += wobble * np.sin(2 * np.pi * 0.7 * T)[:, None] * rng.normal(size=3) / np.sqrt(3)
    X = np.concatenate([np.repeat(parent[None], F, axis=0), child], axis=1) + rng.normal(0, sigma, (F, 8, 3))
    labels = [f"p{k}" for k in range(4)] + ["c0", "c1", "c2", "axis"]
    segments = {"parent": labels[:4], "child": labels[4:]}
    joint = {"name": "knee", "parent": "parent", "child": "child",
             "evidence": {"type": {"main_rotation_deg": float(np.degrees(np.std(angle)))}}}
    found = markers_on_joints(X, labels, segments, [joint])
    assert {m["marker"] for m in found} == {"axis"}
    (m,) = found
    assert m["segment"] == "child" and m["also_with"] == "parent" and "axis or centre" in m["note"]


def test_joints_that_hardly_turn_are_not_checked():
    """Two segments that hardly move relative to each other: every marker stays still in both frames, and that is
    not evidence of anything; nothing is reported."""
    rng = np.random.default_rng(1)
    X = np.repeat(rng.uniform(-100, 100, size=(1, 8, 3)), F, axis=0) + rng.normal(0, 0.3, (F, 8, 3))
    labels = [f"m{k}" for k in range(8)]
    joint = {"name": "j", "parent": "a", "child": "b", "evidence": {"type": {"main_rotation_deg": 2.0}}}
    assert markers_on_joints(X, labels, {"a": labels[:4], "b": labels[4:]}, [joint]) == []


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16))
def test_a_segment_never_seen_whole_in_the_checked_frames_reports_nothing(seed):
    """Two three-marker segments joined by a turning joint, but the child's markers are never all visible in one
    frame (one always occluded, in turn): no pose, so no marker is said to move with it, and the body-frame
    deviations are infinite (not rigid) rather than an error."""
    from identcheck.infer.body_frames import body_deviation, is_rigid

    rng = np.random.default_rng(seed)
    angle = np.radians(30) * np.sin(2 * np.pi * 0.5 * T)
    turn = Rotation.from_rotvec(angle[:, None] * np.array([1.0, 0, 0])).as_matrix()
    parent = rng.uniform(-100, 100, size=(3, 3)) + [0, 0, 200]
    child = rng.uniform(-100, 100, size=(3, 3)) - [0, 0, 200]
    xyz = np.concatenate([np.broadcast_to(parent, (F, 3, 3)), np.einsum("fij,mj->fmi", turn, child)], axis=1)
    xyz = xyz + rng.normal(0, 0.3, xyz.shape)
    for f in range(F):
        xyz[f, 3 + f % 3] = np.nan
    labels = ["P1", "P2", "P3", "C1", "C2", "C3"]
    joint = {"name": "P_C", "parent": "P", "child": "C", "evidence": {"type": {"main_rotation_deg": 17.0}}}
    assert markers_on_joints(xyz, labels, {"P": labels[:3], "C": labels[3:]}, [joint]) == []
    dev, amp = body_deviation(xyz, [3, 4, 5], [0, 1])
    assert np.all(np.isinf(dev)) and np.all(amp == 1.0)
    assert not is_rigid(xyz, [2, 3, 4, 5], 15.0)
