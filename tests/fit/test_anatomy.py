"""The ISB pelvis frame and the hip centre in it: independent of where the subject stands and faces, and the fit's
centre lands where the simulator put it, in that frame."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from identcheck import cli
from identcheck.fit.anatomy import davis, harrington, pelvis_frame, pelvis_markers
from identcheck.simulate.rigid import load_truth
import identcheck as ic

ROOT = Path(__file__).resolve().parents[2]


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_point_in_the_pelvis_frame_does_not_depend_on_the_pose(seed):
    """Random pelvis markers and a random point, moved by random rigid motions: the point's coordinates in the ISB
    frame stay the same, the frame is a rotation with z from left to right ASIS and its origin mid-ASIS."""
    rng = np.random.default_rng(seed)
    right, left = np.array([0.0, 0.0, 110.0]) + rng.normal(0, 5, 3), np.array([0.0, 0.0, -110.0]) + rng.normal(0, 5, 3)
    post = np.array([-150.0, 20.0, 0.0]) + rng.normal(0, 10, 3)
    point = rng.normal(0, 80, 3)
    moves = Rotation.random(6, random_state=int(rng.integers(2**31)))
    shifts = rng.normal(0, 1000, (6, 3))
    place = lambda p: moves.apply(p) + shifts                            # noqa: E731  (6, 3): six poses
    R, o, width, depth = pelvis_frame(place(right), place(left), place(post))
    local = np.einsum("fji,fj->fi", R, place(point) - o)
    np.testing.assert_allclose(local, np.repeat(local[:1], 6, axis=0), atol=1e-8)
    np.testing.assert_allclose(np.einsum("fji,fjk->fik", R, R), np.broadcast_to(np.eye(3), (6, 3, 3)), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    z = (place(right) - place(left))
    np.testing.assert_allclose(R[:, :, 2], z / np.linalg.norm(z, axis=1, keepdims=True), atol=1e-12)
    np.testing.assert_allclose(o, (place(right) + place(left)) / 2, atol=1e-9)
    assert abs(width - np.linalg.norm(right - left)) < 1e-6


def test_harrington_is_the_published_regression_and_mirrors():
    """Harrington et al. 2007 with PW 230, PD 150: x = -0.24 PD - 9.9, y = -0.30 PW - 10.9, z = ±(0.33 PW + 7.3)."""
    np.testing.assert_allclose(harrington(230.0, 150.0, right=True), [-45.9, -79.9, 83.2], atol=1e-9)
    np.testing.assert_allclose(harrington(230.0, 150.0, right=False), [-45.9, -79.9, -83.2], atol=1e-9)


def test_pelvis_markers_are_recognised_by_their_usual_names():
    assert pelvis_markers(["LASI", "RASI", "SACR", "RGT"]) == {"right_asis": "RASI", "left_asis": "LASI",
                                                              "posterior": ["SACR"]}
    assert pelvis_markers(["R.ASIS", "L.ASIS", "V.Sacral"])["posterior"] == ["V.Sacral"]
    assert pelvis_markers(["rasis", "lasis", "rpsis", "lpsis"])["posterior"] == ["rpsis", "lpsis"]
    assert pelvis_markers(["RASI", "LASI"]) is None


def test_fit_reports_the_hip_where_the_simulator_put_it_in_the_isb_frame(tmp_path, capsys):
    leg = str(ROOT / "examples" / "leg.toml")
    trial, truth = tmp_path / "leg.trc", tmp_path / "truth.json"
    assert cli.main(["simulate", leg, "--out", str(trial), "--truth", str(truth), "--seed", "8", "--noise-mm", "0.5",
                     "--frames", "400"]) == 0
    capsys.readouterr()
    model = tmp_path / "leg_subject.toml"        # the same leg, with the subject's leg length for Davis
    model.write_text((ROOT / "examples" / "leg.toml").read_text() + "\n[subject]\nleg_length_mm = 880\n")
    cli.main(["fit", str(model), str(trial), "--json"])
    hip = json.loads(capsys.readouterr().out)["anatomical"]["hips"]["hip_r"]
    t, tr = ic.read_trial(trial), load_truth(truth)
    R, o, width, depth = pelvis_frame(t.marker("RASI"), t.marker("LASI"), t.marker("SACR"))
    want = np.median(np.einsum("fji,fj->fi", R, tr.centre_world("hip_r") - o), axis=0)
    assert np.linalg.norm(np.array(hip["functional_centre"]) - want) < 2.0
    reg = harrington(width, depth, right=want[2] > 0)
    assert abs(hip["distance_mm"] - np.linalg.norm(want - reg)) < 2.0
    dav = davis(880, width, 7.0, right=want[2] > 0)           # marker diameter: the default 14 mm
    assert np.allclose(hip["davis_1991"], dav, atol=0.5)
    assert abs(hip["davis_distance_mm"] - np.linalg.norm(want - dav)) < 2.0


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), leg=st.floats(500, 1100), width=st.floats(180, 300),
       depth=st.floats(120, 200), diameter=st.floats(6, 25))
def test_davis_centre_is_plug_in_gaits_written_in_its_own_frame(seed, leg, width, depth, diameter):
    """Davis's centre placed in the world two ways: through the ISB frame (identcheck) and through Plug-in Gait's
    pelvis frame written here from its definition (origin mid-ASIS, Y from the right to the left ASIS, X anterior
    in the plane of the ASIS and the sacrum, Z = X × Y up; right hip Y = C sin θ − W/2, left its mirror). A
    pelvis at a random pose; both hips agree to 1e-9 mm, the right one on the right ASIS's side, below and
    behind the ASIS."""
    rng = np.random.default_rng(seed)
    R, t = Rotation.random(random_state=rng).as_matrix(), rng.normal(0, 1000, 3)
    place = lambda p: R @ p + t
    rasi, lasi, sacr = place(np.array([0, -width / 2, 0])), place(np.array([0, width / 2, 0])), \
        place(np.array([-depth, 0, 0]))
    # Plug-in Gait's frame, from its definition
    Y = (lasi - rasi) / np.linalg.norm(lasi - rasi)
    mid = (rasi + lasi) / 2
    back = mid - sacr
    X = back - (back @ Y) * Y
    X /= np.linalg.norm(X)
    Z = np.cross(X, Y)
    c = 0.115 * leg - 15.3
    reach = 0.1288 * leg - 48.56 + diameter / 2
    th, be = np.deg2rad(28.4), np.deg2rad(18.0)
    px = c * np.cos(th) * np.sin(be) - reach * np.cos(be)
    pz = -c * np.cos(th) * np.cos(be) - reach * np.sin(be)
    py = c * np.sin(th) - width / 2
    pig = {True: mid + px * X + py * Y + pz * Z, False: mid + px * X - py * Y + pz * Z}
    # identcheck: Davis in the ISB frame, placed in the world through it
    Ri, o, w, _ = pelvis_frame(rasi[None], lasi[None], sacr[None])
    for right in (True, False):
        ours = o[0] + Ri[0] @ davis(leg, w, diameter / 2, right)
        assert np.linalg.norm(ours - pig[right]) < 1e-9
        side = rasi if right else lasi
        assert np.linalg.norm(ours - side) < np.linalg.norm(ours - (lasi if right else rasi))
        assert (ours - mid) @ Z < 0 and (ours - mid) @ X < 0
