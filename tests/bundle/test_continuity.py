"""Joint angles that jump between two frames: a hinge angle that turns half a turn in one frame is a jump, and the
joint is not called determined; real motion, however fast, is not a jump. A swap of two markers on a two-marker
segment, the way such a jump arose, is now caught by ``fit``'s label screen before the fit."""
from __future__ import annotations

import contextlib
import io
import json

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck import cli
from identcheck.trial import Trial


def _fit(path, model) -> tuple[int, dict]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        rc = cli.main(["fit", str(model), str(path), "--json"])
    return rc, json.loads(out.getvalue())


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10 ** 5), start=st.floats(0.3, 0.7))
def test_a_swap_of_the_two_foot_markers_is_left_out_before_it_can_jump(examples, tmp_path_factory, seed, start):
    """The bundled leg's foot carries two markers (heel, toe); exchanged from some frame on, the rigid model would fit
    by turning the foot about the ankle's axis at that frame (an angle jump, which leaves the ankle undetermined:
    :func:`identcheck.bundle.continuity.angle_jumps`, tested directly below). ``fit``'s label screen now reads the
    exchange from the two trajectories going on under each other's label, leaves the shorter side out for the two
    markers and says so; no jump is left, and the ankle is determined from the rest, as on the clean trial. Where the
    foot steps nearly as far in one frame as its markers are apart, the trajectories cannot show the exchange (seed
    334: 54 and 81 mm steps, 63 mm apart); the jump then does, as before."""
    tmp = tmp_path_factory.mktemp("swap")
    clean = tmp / "leg.trc"
    with contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(["simulate", str(examples / "leg.toml"), "--out", str(clean), "--frames", "400",
                         "--noise-mm", "0.5", "--seed", str(seed)]) == 0
    trial = Trial.from_file(clean)
    xyz = trial.as_array()
    a, b = trial.labels.index("RHEE"), trial.labels.index("RTOE")
    row = int(start * trial.n_frames)
    xyz[row:, [a, b]] = xyz[row:, [b, a]]
    swapped = tmp / "swapped.trc"
    Trial(xyz, trial.labels, trial.rate_hz).to_file(swapped)
    rc, rep = _fit(swapped, examples / "leg.toml")
    swaps = [w for w in rep["warnings"] if w["kind"] == "label_swap"]
    jumps = [w for w in rep["warnings"] if w["kind"] == "angle_jump"]
    ankle = rep["joints"]["ankle_r"]
    if swaps:              # read from the trajectories: the shorter side is left out, and nothing jumps
        shorter = [0, row - 1] if row - 1 <= trial.n_frames - 1 - row else [row, trial.n_frames - 1]
        assert [(sorted(w["markers"]), w["frames"]) for w in swaps] == [(["RHEE", "RTOE"], shorter)]
        assert not jumps and ankle["practical"]["verdict"] == "determined"
    else:                  # a foot stepping as far in a frame as its markers are apart: the jump is what shows it
        assert ankle["practical"]["verdict"] == "undetermined" and not ankle["unique"] and rc == 1
        assert all(hi is None for _, hi in ankle["marker_distances_ci95"].values())
        assert all(w["joints"] == ["ankle_r"] and w["frames"] == [row - 1, row] for w in jumps)
        assert jumps or "angle jumps" not in ankle["practical"]["reason"]
    rc0, rep0 = _fit(clean, examples / "leg.toml")
    assert not [w for w in rep0["warnings"] if w["kind"] in ("angle_jump", "label_swap")]
    assert rep0["joints"]["ankle_r"]["practical"]["verdict"] == "determined"


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10 ** 6), share=st.floats(0.01, 0.95), rate=st.sampled_from([50.0, 100.0, 240.0, 500.0]))
def test_fast_turns_are_not_jumps(seed, share, rate):
    """A hinge, and a ball joint between two posed segments, turning at up to 95 % of the limit (4300 deg/s at 50 Hz,
    8600 at 100 Hz, 10 000 deg/s beyond: a pitcher's shoulder) are not jumps; a half turn in one frame is."""
    from identcheck.bundle.continuity import jump_limit_deg

    deg_s = share * jump_limit_deg(rate) * rate
    from types import SimpleNamespace

    from identcheck.bundle.continuity import angle_jumps
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    F = 200
    t = np.arange(F) / rate
    amp = np.deg2rad(rng.uniform(20, 170))
    w = np.deg2rad(deg_s) / amp
    theta = amp * np.sin(w * t)
    axis = rng.normal(size=3)
    rel = Rotation.from_rotvec(theta[:, None] * axis / np.linalg.norm(axis)).as_matrix()
    chain = SimpleNamespace(joints=["h", "b"], types={"h": "revolute", "b": "spherical"},
                            parent={"h": "p", "b": "p"}, child={"h": "c", "b": "d"},
                            seg_markers={"p": np.array([0, 1, 2]), "c": np.array([3]), "d": np.array([4, 5, 6])})
    local = rng.normal(size=(7, 3)) * 100.0             # markers spread on their segments (not on one line)
    fit = SimpleNamespace(chain=chain, state=SimpleNamespace(theta={"h": theta}, rel_R={"b": rel}, local=local,
                                                             c_child={"b": np.zeros(3)}))
    assert angle_jumps(fit, np.zeros((F, 7, 3)), rate) == {}
    theta2 = theta.copy()
    theta2[F // 2:] += np.pi                            # half a turn in one frame: a jump
    fit2 = SimpleNamespace(chain=chain, state=SimpleNamespace(theta={"h": theta2}, rel_R={"b": rel}, local=local,
                                                              c_child={"b": np.zeros(3)}))
    assert set(angle_jumps(fit2, np.zeros((F, 7, 3)), rate)) == {"h"}


def test_a_hinge_below_a_segment_not_posed_by_itself_is_not_judged():
    """A minimal leg's knee (a one-marker thigh below a ball hip): the thigh's roll in each frame is barely seen, so
    the fitted hinge angle may turn half a turn between frames without any swap (it did, on held-out minimal
    legs): no jump is claimed there."""
    from types import SimpleNamespace

    from identcheck.bundle.continuity import angle_jumps

    F = 100
    theta = np.zeros(F)
    theta[50:] = np.pi
    chain = SimpleNamespace(joints=["hip", "knee"], types={"hip": "spherical", "knee": "revolute"},
                            parent={"hip": "pelvis", "knee": "thigh"}, child={"hip": "thigh", "knee": "shank"},
                            seg_markers={"pelvis": np.array([0, 1, 2]), "thigh": np.array([3]), "shank": np.array([4])})
    spread = np.random.default_rng(1).normal(size=(5, 3)) * 100.0     # markers' places, not on one line
    fit = SimpleNamespace(chain=chain, state=SimpleNamespace(theta={"knee": theta}, rel_R={"hip": np.tile(np.eye(3),
                                                                                                  (F, 1, 1))},
                                                             local=spread, c_child={"hip": np.zeros(3)}))
    assert angle_jumps(fit, np.zeros((F, 5, 3)), 100.0) == {}


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10 ** 6), hidden=st.sampled_from(["parent", "child", "none"]),
       left=st.integers(0, 2), width=st.integers(2, 30))
def test_a_jump_where_the_markers_do_not_pose_both_segments_is_not_judged(seed, hidden, left, width):
    """A ball joint between a four-marker pelvis and a three-marker thigh turns half a turn in one frame. Where the
    markers seen there pose both segments, that is a jump; where either segment keeps fewer than three of its markers
    (with the hip's centre: two of the thigh's) on either side of it, the fitted angle follows the joints, not the
    markers, and no jump is claimed (the bundled walking2 trial's hip had 'jumped' 174 deg where its pelvis had no
    marker seen)."""
    from types import SimpleNamespace

    from identcheck.bundle.continuity import angle_jumps
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    F, k = 120, 60
    rel = Rotation.from_rotvec(rng.normal(0, 0.01, (F, 3))).as_matrix()
    rel[k + 1:] = Rotation.from_rotvec([0.0, np.pi * 0.95, 0.0]).as_matrix() @ rel[k + 1:]
    chain = SimpleNamespace(joints=["hip"], types={"hip": "spherical"}, parent={"hip": "pelvis"},
                            child={"hip": "thigh"},
                            seg_markers={"pelvis": np.array([0, 1, 2, 3]), "thigh": np.array([4, 5, 6])})
    fit = SimpleNamespace(chain=chain, state=SimpleNamespace(theta={}, rel_R={"hip": rel},
                                                             local=rng.normal(size=(7, 3)) * 100.0,
                                                             c_child={"hip": np.zeros(3)}))
    data = rng.normal(size=(F, 7, 3))
    gap = slice(k + 1 - width // 2, k + 1 + width // 2)
    if hidden == "parent":              # the pelvis keeps `left` of its four markers: fewer than three
        data[gap, left:4] = np.nan
    elif hidden == "child":             # the thigh keeps `left - 1` or fewer: with the hip's centre, under three
        data[gap, 4 + max(left - 1, 0):7] = np.nan
    found = angle_jumps(fit, data, 100.0)
    assert (set(found) == {"hip"}) == (hidden == "none")
