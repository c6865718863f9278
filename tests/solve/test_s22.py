"""S22 (Pham et al., section V-A): exact data give the true constants and centres at zero cost,
the circle geometry agrees with brute force, noise moves the answer proportionally, and
degenerate input is refused by name."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import identcheck.solve.s22 as s22
from identcheck.errors import DegenerateError, InputError
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.solve.gamage_lasenby import gamage_lasenby
from identcheck.solve.s22 import (choose_v, closest_points, joint_centres, realisable_radii, s22_cost,
                                  s22_frames, solve_s22, spheres_circle)
from test_gamage_lasenby import hip_trials, make_hip

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "hip_s22.toml"


def _solve(p, **kw):
    aw, bw = p["aw"], p["bw"]
    return solve_s22(aw[:, 0], aw[:, 1], bw[:, 0], bw[:, 1], a3=aw[:, 2], **kw)


def _local(p, seed=0):
    aw, bw = p["aw"], p["bw"]
    return s22_frames(aw[:, 0], aw[:, 1], bw[:, 0], bw[:, 1], seed)


# ---------------------------------------------------------------------- exact data
@given(hip_trials())
def test_cost_is_zero_at_the_truth_and_centres_are_exact(kw):
    p = make_hip(**kw)
    b1, b2, h, rot, _ = _local(p)
    assert s22_cost(p["truth"], b1, b2, h) < 1e-18 * max(1.0, np.mean(h)) ** 2
    j, gap = joint_centres(p["truth"], b1, b2)
    true_local = np.einsum("fij,fj->fi", rot, p["cw"] - p["aw"][:, 0])
    assert np.abs(j - true_local).max() < 1e-8 and gap.max() < 1e-8


@pytest.mark.slow
@settings(max_examples=12)
@given(hip_trials())
def test_s22_recovers_the_truth(kw):
    p = make_hip(**kw)
    res = _solve(p)
    scale = max(np.abs(p["truth"]).max(), 1.0)
    assert np.abs(res.params - p["truth"]).max() < 1e-7 * scale
    assert np.abs(res.centres_world - p["cw"]).max() < 1e-6
    assert res.cost_mm2 < 1e-14 * scale**2 and res.sqrt_cost_mm < 1e-6
    assert res.paper_cost_mm2 >= res.cost_mm2 - 1e-14 * scale**2 and res.unique


@pytest.mark.parametrize("seed", [0, 4, 11])
def test_s22_without_the_linear_seed(seed, monkeypatch):
    """The fallback seeds (sphere fit, random starts) find the truth on their own."""
    monkeypatch.setattr(s22, "_linear_seed", lambda b1, b2: None)
    p = make_hip(seed, n_frames=25)
    res = _solve(p, n_random=12)
    assert "linear" not in {s["source"] for s in res.starts}
    assert np.abs(res.params - p["truth"]).max() < 1e-6 * np.abs(p["truth"]).max()


@pytest.mark.parametrize("seed", [0, 1])
def test_result_does_not_depend_on_v(seed):
    """Rolling F_S22 about A1A2 maps Γ onto itself: two seeds (two v) give the same joint."""
    p = make_hip(seed, n_frames=20, noise=0.5)
    r0, r1 = _solve(p, seed=0), _solve(p, seed=99)
    assert not np.allclose(r0.v, r1.v)
    assert np.allclose(r0.params, r1.params, atol=1e-5)
    assert np.allclose(r0.centres_world, r1.centres_world, atol=1e-4)


def test_simulated_model_file():
    """examples/hip_s22.toml through simulate(): S22 and GL find Truth.centre_world."""
    sim = simulate(Model.from_toml(EXAMPLE), n_frames=30, rate_hz=1 / 0.095, rom_deg=40, seed=2)
    m = {k: sim.clean.marker(k) for k in ("L5", "LPELVIS", "RPELVIS", "RHIP", "RKNEE")}
    truth = sim.truth.centre_world("hip_r")
    res = solve_s22(m["L5"], m["LPELVIS"], m["RHIP"], m["RKNEE"], a3=m["RPELVIS"])
    gl = gamage_lasenby(m["L5"], m["LPELVIS"], m["RPELVIS"], [m["RHIP"], m["RKNEE"]])
    assert np.abs(res.centres_world - truth).max() < 1e-6
    assert np.abs(gl.centres_world - truth).max() < 1e-8
    dist = sim.truth.marker_distances("hip_r")
    assert np.allclose(res.params[2:], [dist["RHIP"], dist["RKNEE"]], atol=1e-6)


# ---------------------------------------------------------------------- circle geometry
@st.composite
def circle_pairs(draw):
    """Γ(d, r) and a random circle Γ' (centre, unit normal, radius), one frame."""
    f = lambda lo, hi: draw(st.floats(lo, hi))  # noqa: E731
    d, r = f(-200, 200), f(1, 200)
    centre = np.array([f(-250, 250) for _ in range(3)])
    normal = np.array([f(-1, 1) for _ in range(3)])
    normal = normal / np.linalg.norm(normal) if np.linalg.norm(normal) > 0.1 else np.array([0.0, 0, 1])
    return d, r, centre, normal, f(0, 200)


@pytest.mark.slow
@given(circle_pairs())
def test_closest_points_match_brute_force(pair):
    d, r, centre, normal, radius = pair
    p, q = closest_points(d, r, centre[None], normal[None], np.array([radius]))
    gap = np.linalg.norm(p - q)
    u = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    t = np.linspace(0, 2 * np.pi, 1500, endpoint=False)
    gam = np.stack([r * np.cos(t), r * np.sin(t), np.full_like(t, d)], -1)
    gam2 = centre + radius * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * v)
    brute = np.linalg.norm(gam[:, None] - gam2[None], axis=-1).min()
    slack = 2 * np.pi / 1500 * (r + radius)             # grid resolution of the brute force
    assert gap <= brute + 1e-9 and gap >= brute - slack
    assert abs(np.hypot(p[0, 0], p[0, 1]) - r) < 1e-9 and abs(p[0, 2] - d) < 1e-9        # P on Γ
    w = q[0] - centre
    assert abs(w @ normal) < 1e-8 and abs(np.linalg.norm(w) - radius) < 1e-8             # Q on Γ'


@given(st.floats(0, 300), st.floats(0, 300), st.floats(1, 300))
def test_realisable_radii_project_onto_the_triangle_inequality(rho1, rho2, length):
    a, b = realisable_radii(np.array(rho1), np.array(rho2), np.array(length))
    assert abs(a - b) <= length * (1 + 1e-12) + 1e-9 and a + b >= length * (1 - 1e-12) - 1e-9
    feasible = abs(rho1 - rho2) <= length <= rho1 + rho2
    if feasible:
        assert np.isclose(a, rho1) and np.isclose(b, rho2)
    else:   # the nearest realisable pair: moved along the normal of the violated constraint
        assert np.isclose(abs(a - rho1), abs(b - rho2))


def test_spheres_circle_points_are_at_the_given_distances():
    rng = np.random.default_rng(0)
    b1, b2 = rng.normal(size=(50, 3)) * 100, rng.normal(size=(50, 3)) * 100
    rho1 = rho2 = np.linalg.norm(b2 - b1, axis=1).max()          # always intersecting
    centre, normal, radius = spheres_circle(b1, b2, rho1, rho2)
    u = np.cross(normal, [1.0, 0, 0])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = centre + radius[:, None] * u
    assert np.allclose(np.linalg.norm(pts - b1, axis=1), rho1) and np.allclose(np.linalg.norm(pts - b2, axis=1), rho2)


@pytest.mark.parametrize("rho1, rho2", [(30.0, 40.0), (250.0, 20.0), (20.0, 250.0)])
def test_non_intersecting_spheres_give_the_best_axis_point(rho1, rho2):
    """Apart or nested spheres: Γ' is the one point minimising the sphere-distance mismatch."""
    b1, b2 = np.zeros((1, 3)), np.array([[0.0, 0, 100]])
    centre, _, radius = spheres_circle(b1, b2, rho1, rho2)
    assert radius[0] == 0
    s = np.linspace(-400, 500, 90001)
    mismatch = (np.abs(s) - rho1) ** 2 + (np.abs(s - 100) - rho2) ** 2
    assert abs(centre[0, 2] - s[np.argmin(mismatch)]) < 0.02
    off = centre[0] + [1.0, 0, 0]                                  # moving off the axis is worse
    m0 = (np.linalg.norm(centre[0]) - rho1) ** 2 + (np.linalg.norm(centre[0] - b2[0]) - rho2) ** 2
    m1 = (np.linalg.norm(off) - rho1) ** 2 + (np.linalg.norm(off - b2[0]) - rho2) ** 2
    assert m1 > m0


def test_choose_v_avoids_the_axis():
    e = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]])
    v = choose_v(e, seed=3)
    assert np.isclose(np.linalg.norm(v), 1) and np.abs(e @ v).max() < 0.95


# ---------------------------------------------------------------------- noise
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_s22_error_scales_with_noise(seed):
    """First order: the same noise draw scaled by 10 moves the constants about 10 times as far."""
    errs = []
    for noise in (1e-3, 1e-2):
        p = make_hip(seed, n_frames=30, noise=noise)
        errs.append(np.abs(_solve(p, n_random=2).params - p["truth"]).max())
    assert 0 < errs[0] < 0.2 and 7 < errs[1] / errs[0] < 13


def test_noisy_trial_reports_its_cost():
    p = make_hip(4, n_frames=40, noise=1.0)
    res = _solve(p)
    assert 0.1 < res.sqrt_cost_mm < 10 and res.gap_mm.max() > 0
    assert np.linalg.norm(res.centres_world - p["cw"], axis=1).mean() < 5
    assert res.as_dict().keys() == {"d", "r", "rho1", "rho2"}


# ---------------------------------------------------------------------- gaps and errors
def test_gaps_drop_frames():
    p = make_hip(6, n_frames=20)
    aw = p["aw"].copy()
    aw[[0, 5], 0] = np.nan
    res = solve_s22(aw[:, 0], aw[:, 1], p["bw"][:, 0], p["bw"][:, 1])
    assert np.isnan(res.centres_world[[0, 5]]).all() and len(res.frames) == 18
    assert np.abs(res.centres_world[res.frames] - p["cw"][res.frames]).max() < 1e-6


def test_too_few_frames():
    p = make_hip(1, n_frames=8)
    with pytest.raises(DegenerateError, match="at least 9 frames.*only 8 of 8"):
        _solve(p)


def test_gaps_leaving_too_few_frames():
    p = make_hip(1, n_frames=12)
    bw = p["bw"].copy()
    bw[:5, 1] = np.nan
    with pytest.raises(DegenerateError, match="only 7 of 12"):
        _solve(dict(p, bw=bw))


def test_nan_only_marker():
    p = make_hip(1)
    bw = p["bw"].copy()
    bw[:, 0] = np.nan
    with pytest.raises(InputError, match="RHIP has no valid sample"):
        solve_s22(p["aw"][:, 0], p["aw"][:, 1], bw[:, 0], bw[:, 1], labels=["L5", "LPELVIS", "RHIP", "RKNEE"])


def test_coincident_parent_markers():
    p = make_hip(1)
    with pytest.raises(DegenerateError, match="A1 and A2 coincide"):
        solve_s22(p["aw"][:, 0], p["aw"][:, 0], p["bw"][:, 0], p["bw"][:, 1])


def test_coincident_child_markers():
    p = make_hip(1)
    with pytest.raises(DegenerateError, match="B1 and B2 coincide"):
        solve_s22(p["aw"][:, 0], p["aw"][:, 1], p["bw"][:, 0], p["bw"][:, 0])
