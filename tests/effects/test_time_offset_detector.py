"""The delay detector's pieces: a velocity that does not dilute the regression, the part of a lag's field the poses
do not absorb, and a one-marker lag on a three-marker segment found at its size by diagnose."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import identcheck as ic
from identcheck.effects.time_offset import shifted, smooth_velocity
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.3, 1.5), st.integers(1, 6))
def test_a_lag_regressed_on_the_smooth_velocity_is_not_diluted(seed, noise, lag_frames):
    """Gait-like motion (0.5-2 Hz, 20-80 mm), white noise: the lag's least-squares estimate from the lagged minus
    the true samples stays within 12 % of the truth (the noisy samples' own spline derivative reads it short)."""
    rng = np.random.default_rng(seed)
    rate, n = 100.0, 1200
    t = np.arange(n) / rate
    f, a, ph = rng.uniform(0.5, 2.0, (3, 3)), rng.uniform(20, 80, (3, 3)), rng.uniform(0, 2 * np.pi, (3, 3))
    x = sum(a[k] * np.sin(2 * np.pi * f[k] * t[:, None] + ph[k]) for k in range(3))[:, None, :]
    tau = lag_frames / rate
    lagged = sum(a[k] * np.sin(2 * np.pi * f[k] * (t[:, None] - tau) + ph[k]) for k in range(3))[:, None, :]
    measured = lagged + rng.normal(0, noise, lagged.shape)
    truth = x + rng.normal(0, noise, x.shape)
    r = measured - truth
    v = smooth_velocity(measured, rate)
    ok = np.isfinite(v)
    estimate = -np.sum(r[ok] * v[ok]) / np.sum(v[ok] ** 2)
    assert abs(estimate - tau) <= 0.12 * tau


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(1e-4, 1e-2))
def test_what_the_poses_absorb_is_taken_out_of_a_field_and_nothing_else(seed, eps):
    """On a fitted leg: a field made by moving the per-frame unknowns (root pose, joint angles) leaves nothing
    (to O(ε)), nor does one marker moved by a constant in its segment's frame (its own position absorbs it); a
    random field keeps most of its norm, never more than all of it; adding a pose field to it leaves what it
    alone leaves (what is absorbed is a projection)."""
    from identcheck.bundle.chain import fit_chain, initial_state
    from identcheck.bundle.score_test import unabsorbed
    from identcheck.bundle.model import Terms, apply_step, forward, n_const
    from identcheck.skeleton import Skeleton

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    data = simulate(model, n_frames=60, noise_mm=0.5, seed=seed % 1000).trial.select(model.markers).as_array()
    chain = Skeleton.from_model(model)
    fit = fit_chain(chain, data, initial_state(chain, data), max_iter=20)
    rng = np.random.default_rng(seed)
    s = fit.state
    R, _t, _c, pred = forward(chain, Terms(), s)
    k = fit.chain.frame_dof()
    step = eps * rng.normal(size=(data.shape[0], k))
    moved = apply_step(chain, Terms(), s, R, step, np.zeros(n_const(chain, Terms())))
    pose_field = (forward(chain, Terms(), moved)[3] - pred) / eps
    noise_field = rng.normal(0, 1.0, data.shape)
    marker = int(rng.integers(chain.n_markers))
    offset_field = np.zeros(data.shape)
    offset_field[:, marker] = fit.seg_R[chain.marker_seg[marker]] @ rng.normal(0, 10.0, 3)
    w = np.ones(data.shape[:2])
    left_pose, left_offset, left_noise, left_sum = unabsorbed(
        fit, w, [pose_field, offset_field, noise_field, pose_field + noise_field])
    assert abs(left_pose) <= 1e-2 * np.sum(pose_field ** 2)
    assert abs(left_offset) <= 1e-6 * np.sum(offset_field ** 2)
    assert 0.5 * np.sum(noise_field ** 2) < left_noise <= np.sum(noise_field ** 2)
    assert abs(left_sum - left_noise) <= 1e-2 * np.sum(pose_field ** 2) + 1e-6 * left_noise


def test_diagnose_names_one_marker_lagging_on_a_three_marker_pelvis():
    """RASI 40 ms late on a 3-marker pelvis, 0.6 mm noise: named a time offset of that marker, about 40 ms."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=1200, noise_mm=0.0, seed=3)
    xyz = sim.trial.as_array().copy()
    k = sim.trial.labels.index("RASI")
    xyz[:, [k]] = shifted(xyz[:, [k]], sim.trial.rate_hz, -0.04, extrapolate=True)
    xyz += np.random.default_rng(3).normal(0, 0.6, xyz.shape)
    trial = sim.trial.replace(xyz=xyz)
    first = ic.diagnose(model, trial).to_dict()["effects"][0]
    assert first["name"] == "time_offset" and first["where"].get("markers") == ["RASI"]
    assert abs(first["where"]["delay_ms"] - 40.0) < 4.0


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 2**16), st.integers(2, 4), st.sampled_from([0.0, 0.4]), st.floats(-0.2, 0.2))
def test_a_segment_late_by_whole_frames_is_found_at_them_and_a_fractional_lag_is_kept(seed, frames, fraction, lean):
    """The shank late by 2-4 whole frames (0.6 mm white noise), the delay's refinement left `lean` frames off the
    truth (as the least-squares delay leans, interpolation lowering the noise too): the whole-frame delay is
    tried and kept, to the millisecond. Late by a fraction more (0.4 frame), the delay stays fractional, within
    1.5 ms of the truth."""
    import identcheck.effects.time_offset as time_offset
    from identcheck.diagnose.workflow import start
    from identcheck.effects.registry import EFFECTS

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=600, noise_mm=0.0, seed=seed)
    xyz = sim.trial.as_array().copy()
    cols = [sim.trial.labels.index(m) for m in model.segments["shank"].markers]
    rate = sim.trial.rate_hz
    lag_s = (frames + fraction) / rate
    xyz[:, cols] = shifted(xyz[:, cols], rate, -lag_s, extrapolate=True)
    xyz += np.random.default_rng(seed).normal(0, 0.6, xyz.shape)
    ctx, h = start(model, sim.trial.replace(xyz=xyz))
    eff = EFFECTS["time_offset"]
    prop = next(p for p in eff.propose(ctx, h) if p.where["segment"] == "shank" and "markers" not in p.where)
    if fraction == 0.0:
        prop.payload["tau"] = lag_s + lean / rate
        steps, time_offset.NEWTON_STEPS = time_offset.NEWTON_STEPS, 0          # the delay as the refinement left it
        try:
            eff.apply(ctx, h, prop)
        finally:
            time_offset.NEWTON_STEPS = steps
        assert prop.where["delay_ms"] == round(1000 * lag_s, 2) or abs(lean) <= time_offset.WHOLE_FRAME_TRY
    else:
        eff.apply(ctx, h, prop)
        assert abs(prop.where["delay_ms"] - 1000 * lag_s) < 1.5


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**16), st.sampled_from(["RASI", "LASI", "SACR"]))
def test_one_marker_lagging_in_overground_walking_is_read_at_its_size(seed, marker):
    """The trial carried forward at 1.3 m/s (overground walking), one pelvis marker 40 ms late, 0.5 mm noise. Most
    of the lag is the marker's mean speed times 40 ms: a constant offset that its own position takes up, which the
    detector must not count as explained by the lag (regressed on the whole velocity field it read 0.5 ms on a
    held-out trial). Its proposal is the strongest single-marker one, at 25-55 ms."""
    from identcheck.diagnose.workflow import start
    from identcheck.effects.registry import EFFECTS

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=800, noise_mm=0.0, seed=seed)
    xyz = sim.trial.as_array().copy()
    xyz[..., 0] += 1300.0 * np.arange(len(xyz))[:, None] / sim.trial.rate_hz
    k = sim.trial.labels.index(marker)
    xyz[:, [k]] = shifted(xyz[:, [k]], sim.trial.rate_hz, -0.04, extrapolate=True)
    xyz += np.random.default_rng(seed).normal(0, 0.5, xyz.shape)
    trial, _ = sim.trial.replace(xyz=xyz).recentred()
    ctx, h = start(model, trial)
    single = [p for p in EFFECTS["time_offset"].propose(ctx, h) if "markers" in p.where]
    assert single and single[0].where["markers"] == [marker]
    assert 25.0 <= single[0].where["delay_ms"] <= 55.0


@settings(max_examples=60, deadline=None)
@given(st.integers(-8, 8).filter(lambda k: k != 0), st.floats(-3.0, 3.0), st.floats(0.5, 50.0))
def test_the_whole_frame_search_climbs_a_single_peaked_profile_to_its_top(peak, start, width):
    """A score profile over whole-frame delays with one peak (a concave parabola about `peak`, the delay's smooth
    profile): started from the whole frames beside any point within 3 frames of it, the search reaches the peak
    and never proposes no delay at all (0 frames)."""
    from identcheck.effects.time_offset import best_whole_frame, whole_frames_beside

    asked = []

    def scored(frames):
        asked.append(frames)
        return -((frames - peak) / width) ** 2

    shift = peak + start
    beside = whole_frames_beside(shift) or [float(round(shift))]
    beside = [b for b in beside if b != 0.0] or [1.0 if shift >= 0 else -1.0]
    assert best_whole_frame(scored, beside) == peak
    assert 0.0 not in asked


@settings(max_examples=40, deadline=None)
@given(st.floats(-6.0, 6.0))
def test_the_whole_frames_beside_a_delay_bracket_it_and_leave_out_no_delay(shift):
    """Beside a fractional shift: its floor and ceiling, 0 left out; beside a whole one (within the tolerance):
    nothing to add."""
    from identcheck.effects.time_offset import WHOLE_FRAME_TRY, whole_frames_beside

    out = whole_frames_beside(shift)
    if abs(round(shift) - shift) <= WHOLE_FRAME_TRY:
        assert out == []
    else:
        assert set(out) == {w for w in (np.floor(shift), np.ceil(shift)) if w != 0.0}
        assert all(abs(w - shift) < 1.0 for w in out)


def _shank_late(seed: int, frames: float, noise_mm: float) -> tuple:
    """A 600-frame trial of the bundled leg with its shank `frames` late and white noise: the context, the rigid fit,
    the shank's columns and the frame rate."""
    from identcheck.diagnose.workflow import start

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=600, noise_mm=0.0, seed=seed)
    xyz = sim.trial.as_array().copy()
    cols = [sim.trial.labels.index(m) for m in model.segments["shank"].markers]
    rate = sim.trial.rate_hz
    xyz[:, cols] = shifted(xyz[:, cols], rate, -frames / rate, extrapolate=True)
    xyz += np.random.default_rng(seed).normal(0, noise_mm, xyz.shape)
    ctx, h = start(model, sim.trial.replace(xyz=xyz))
    return ctx, h, cols, rate


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**16), st.floats(1.3, 1.7))
def test_a_delay_left_short_by_more_than_a_frame_is_walked_to_the_truth(seed, short):
    """The shank 3 whole frames late (0.6 mm white noise), the refinement left 1.3-1.7 frames short of it (as the
    least-squares delay is held at half frames where interpolating lowers the noise: a held-out pelvis 1.94 frames
    late was left at 0.52 and at 1.50): the whole-frame search walks on to the 3 frames (the nearest whole frame
    alone was 1 or 2)."""
    import identcheck.effects.time_offset as time_offset
    from identcheck.effects.registry import EFFECTS

    ctx, h, cols, rate = _shank_late(seed, 3.0, 0.6)
    eff = EFFECTS["time_offset"]
    prop = next(p for p in eff.propose(ctx, h) if p.where["segment"] == "shank" and "markers" not in p.where)
    prop.payload["tau"] = (3.0 - short) / rate
    steps, time_offset.NEWTON_STEPS = time_offset.NEWTON_STEPS, 0
    try:
        eff.apply(ctx, h, prop)
    finally:
        time_offset.NEWTON_STEPS = steps
    assert prop.where["delay_ms"] == 30.0


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**16), st.integers(3, 5), st.sampled_from([-1.0, 1.0]))
def test_a_delay_left_at_a_whole_frame_beside_the_truth_is_walked_to_it(seed, frames, off):
    """The shank 3-5 whole frames late (0.6 mm white noise), the refinement left exactly a whole frame off (a held-out
    thigh 4 frames late in gait: Newton stopped at 3.005 frames, where no fractional part started the whole-frame
    search, and the delay was named second, after skin): the search starts from a whole frame too."""
    import identcheck.effects.time_offset as time_offset
    from identcheck.effects.registry import EFFECTS

    ctx, h, cols, rate = _shank_late(seed, frames, 0.6)
    eff = EFFECTS["time_offset"]
    prop = next(p for p in eff.propose(ctx, h) if p.where["segment"] == "shank" and "markers" not in p.where)
    prop.payload["tau"] = (frames + off) / rate + 0.004 / rate      # within WHOLE_FRAME_TRY of a whole frame
    steps, time_offset.NEWTON_STEPS = time_offset.NEWTON_STEPS, 0
    try:
        eff.apply(ctx, h, prop)
    finally:
        time_offset.NEWTON_STEPS = steps
    assert prop.where["delay_ms"] == round(1000 * frames / rate, 2)


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**16), st.integers(5, 8))
def test_a_delay_refitted_from_a_fresh_start_too_reaches_the_noise(seed, frames):
    """The shank 5-8 frames late (0.5 mm noise): the rigid fit's angles bend to the lag. The delay's refit with the
    lag undone, taken from the better of the bent fit and a fresh start, leaves no more than the refit from the bent
    fit alone, and within 5 % of the noise's expected share."""
    from identcheck.effects.time_offset import TimeOffset

    ctx, h, cols, rate = _shank_late(seed, frames, 0.5)
    both = TimeOffset._shifted_fit(ctx, h, h, cols, frames / rate, fresh=True)
    warm = TimeOffset._shifted_fit(ctx, h, h, cols, frames / rate)
    assert ctx.rss(both) <= ctx.rss(warm)
    expected = 0.5 ** 2 * (3 * both.weights.sum() - both.fit.n_params)
    assert both.rss < 1.05 * expected


@settings(max_examples=60, deadline=None)
@given(st.floats(-8.0, 8.0))
def test_the_walk_starts_beside_a_delay_at_it_when_whole_and_never_at_no_delay(shift):
    """The whole-frame search starts from the two whole frames beside a fractional delay, from a whole delay itself,
    and from a frame on its side when the delay is within WHOLE_FRAME_TRY of 0; never from 0."""
    from identcheck.effects.time_offset import WHOLE_FRAME_TRY, walk_start

    out = walk_start(shift)
    assert out and 0.0 not in out and all(w == round(w) for w in out)
    if abs(round(shift) - shift) > WHOLE_FRAME_TRY:
        assert all(abs(w - shift) < 1.0 for w in out)
    elif round(shift) == shift and shift != 0.0:
        assert out == [shift]
    elif round(shift) == 0:
        assert out == [1.0 if shift >= 0 else -1.0]


@settings(max_examples=60, deadline=None)
@given(st.floats(-8.0, 8.0))
def test_a_delay_within_the_tolerance_of_a_whole_frame_is_that_frame_but_never_no_delay(shift):
    """Within WHOLE_FRAME_TRY of a whole frame other than 0 a delay is taken as that frame; otherwise it is kept."""
    from identcheck.effects.time_offset import WHOLE_FRAME_TRY, nearest_whole

    out = nearest_whole(shift)
    if round(shift) != 0 and abs(round(shift) - shift) <= WHOLE_FRAME_TRY:
        assert out == round(shift)
    else:
        assert out == shift


def test_a_delay_counts_one_parameter_among_explanations_the_data_cannot_tell_apart():
    """Ranking equal explanations by their parameters counts a delay's one, not the samples its shift moved past
    the trial's end nor the noise interpolation removes (charged in its score): a pelvis 4 frames late had been
    charged 49 and named after a hip centre moving with its angles (31) that scored less."""
    from types import SimpleNamespace

    from identcheck.diagnose.workflow import simplest_among_equals
    from identcheck.effects.registry import EFFECTS

    class Fake(SimpleNamespace):
        def n_params(self):
            return self.k

    h = Fake(k=1000)
    delay, translation = EFFECTS["time_offset"], EFFECTS["joint_translation"]
    p_delay = SimpleNamespace(where={"segment": "pelvis", "delay_ms": 40.0}, payload={})
    p_move = SimpleNamespace(where={"joint": "hip"}, payload={})
    tried = [(145_133.3, translation, p_move, Fake(k=1031)), (145_100.0, delay, p_delay, Fake(k=1049))]
    assert simplest_among_equals(tried, h, 0.0)[0][1] is delay
    assert delay.own_params(p_delay, h, Fake(k=1049)) == 1.0
    assert translation.own_params(p_move, h, Fake(k=1031)) == 31
    far = [(145_133.3, translation, p_move, Fake(k=1031)), (100_000.0, delay, p_delay, Fake(k=1049))]
    assert simplest_among_equals(far, h, 0.0)[0][1] is translation


def _rigid_cluster(rng, n_markers: int, n_frames: int, rate: float, scale: float = 1.0) -> np.ndarray:
    """`n_markers` points fixed on one body turning and moving smoothly (a few tenths of a hertz to 2 Hz, tens of
    degrees, tens of centimetres, all times `scale`): (F, M, 3) mm."""
    from scipy.spatial.transform import Rotation

    t = np.arange(n_frames) / rate
    f, a, ph = rng.uniform(0.3, 2.0, (3, 3)), rng.uniform(0.2, 0.7, (3, 3)), rng.uniform(0, 2 * np.pi, (3, 3))
    angles = scale * sum(a[k] * np.sin(2 * np.pi * f[k] * t[:, None] + ph[k]) for k in range(3))
    moves = scale * sum(rng.uniform(50, 300, 3) * np.sin(2 * np.pi * f[k] * t[:, None] + ph[k, ::-1])
                        for k in range(3))
    local = rng.normal(0, 80.0, (n_markers, 3))
    return np.einsum("fij,mj->fmi", Rotation.from_rotvec(angles).as_matrix(), local) + moves[:, None, :]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 4), st.integers(1, 5), st.booleans(), st.floats(0.3, 1.0))
def test_a_lag_read_from_the_distances_to_segment_mates_has_its_sign_and_size(seed, n_markers, frames, late, noise):
    """One marker of a moving rigid cluster late (or early) by 1-5 frames, white noise: the delay read from its
    distances to the others alone has the truth's sign and is within 35 % of it (linearised in the delay), and its
    χ² earns the parameter by far (ln 3N is about 9 here). Without a delay, its χ² is noise's: below the parameter's
    charge that proposes it (a χ²₁ beyond 9 has odds of 0.3 %; the charge is the production's own, ``ln 3N``, for
    1000 frames of 2-4 markers), also on a cluster moving a hundredth as much, where a delay of a fraction of a frame
    undone through a spline had counted the noise it smooths as explained (χ² 52-126 on 3 of 40 such clusters)."""
    from identcheck.effects.time_offset import lag_from_rigidity

    rng = np.random.default_rng(seed)
    rate = 100.0
    xyz = _rigid_cluster(rng, n_markers, 1000, rate)
    clean = xyz + rng.normal(0, noise, xyz.shape)
    mates = list(range(1, n_markers))
    charge = np.log(3 * 1000 * n_markers)
    _tau, chi2 = lag_from_rigidity(clean, smooth_velocity(clean, rate), 0, mates, rate)
    assert chi2 < charge
    slow = _rigid_cluster(rng, n_markers, 1000, rate, scale=0.01)      # a few mm, hundredths of a radian
    slow += rng.normal(0, noise, slow.shape)
    _tau, chi2 = lag_from_rigidity(slow, smooth_velocity(slow, rate), 0, mates, rate)
    assert chi2 < charge
    tau = (1 if late else -1) * frames / rate
    xyz[:, [0]] = shifted(xyz[:, [0]], rate, -tau, extrapolate=True)
    xyz += rng.normal(0, noise, xyz.shape)
    estimate, chi2 = lag_from_rigidity(xyz, smooth_velocity(xyz, rate), 0, mates, rate)
    assert abs(estimate - tau) <= 0.35 * abs(tau)
    assert chi2 > charge


TWO_MARKER_THIGH = """
units = "mm"
[segments.pelvis]
markers = ["RASI", "LASI", "RPSI", "LPSI"]
[segments.thigh]
markers = ["RTHI", "RKNE"]
length_mm = 430
[segments.shank]
markers = ["RTIB", "RANK"]
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


def test_a_delay_read_from_the_distances_is_fitted_from_where_it_was_read(tmp_path):
    """RTHI 30 ms late on a thigh carrying only RTHI and RKNE: the proposal read from RTHI's distance to RKNE is
    among the delay's proposals, always fitted (its strength is not on the residual detector's scale), and its fit
    starts from the delay it read rather than Newton's on the joint model's residual (which had gone from 2.2 frames
    back to -0.07 on held-out draw 56, trial 89): it ends at the 3 whole frames, 30 ms."""
    from identcheck.diagnose.workflow import start
    from identcheck.effects.registry import EFFECTS

    path = tmp_path / "two_marker_thigh.toml"
    path.write_text(TWO_MARKER_THIGH)
    model = Model.from_toml(path)
    sim = simulate(model, n_frames=1000, noise_mm=0.0, seed=5)
    xyz = sim.trial.as_array().copy()
    k = sim.trial.labels.index("RTHI")
    xyz[:, [k]] = shifted(xyz[:, [k]], sim.trial.rate_hz, -0.03, extrapolate=True)
    xyz += np.random.default_rng(5).normal(0, 0.8, xyz.shape)
    ctx, h = start(model, sim.trial.replace(xyz=xyz).recentred()[0])
    eff = EFFECTS["time_offset"]
    read = eff.rigidity_proposals(ctx, h)
    prop = next(p for p in read if p.where["markers"] == ["RTHI"])
    assert prop.always_fit and 20.0 <= prop.where["delay_ms"] <= 40.0
    eff.apply(ctx, h, prop)
    assert prop.where["delay_ms"] == 30.0


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1000, 4000), st.floats(0.2, 20.0), st.floats(-50.0, 50.0))
def test_the_spread_of_gains_reads_the_noise_and_not_the_mean_gain(seed, n, s, mean):
    """Per-frame gains that are independent noise of spread `s` about a mean up to 50 times larger: the spread read
    of their sum is √F·s within 30 % (100-400 blocks: the reading itself spreads about 9 % at 100), and the mean
    does not enter it."""
    from identcheck.effects.time_offset import spread_of_gains

    d = np.random.default_rng(seed).normal(0.0, s, n)
    assert 0.7 <= spread_of_gains(d) / (s * np.sqrt(n)) <= 1.3
    assert spread_of_gains(d + mean * s) == pytest.approx(spread_of_gains(d), rel=1e-6)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(20, 200), st.integers(2, 6), st.integers(-6, 6).filter(bool))
def test_a_shifted_markers_own_terms_meet_themselves_and_leave_no_gain(seed, n, m, k):
    """Per-sample terms of a fit, and the same terms with some markers' taken `k` frames later (a placebo whose
    shift re-pairs no noise): the aligned per-frame gains are zero on every frame, where the plain per-frame
    differences are not."""
    from identcheck.effects.time_offset import aligned_gains

    rng = np.random.default_rng(seed)
    before = rng.exponential(1.0, (n, m))
    idx = sorted(rng.choice(m, int(rng.integers(1, m + 1)), replace=False).tolist())
    after = before.copy()
    src = np.arange(n) + k
    ok = (src >= 0) & (src < n)
    after[:, idx] = 0.0
    after[np.flatnonzero(ok)[:, None], idx] = before[src[ok]][:, idx]
    assert np.allclose(aligned_gains(before, after, idx, k), 0.0, atol=1e-12)
    assert not np.allclose(np.sum(before - after, axis=1), 0.0)
    # frames the shift empties are weighed by neither fit: their terms are 0 in both, and still nothing is left
    fitted = np.ones((n, m), dtype=bool)
    fitted[np.flatnonzero(~ok)[:, None], idx] = False
    before[~fitted], after[~fitted] = 0.0, 0.0
    assert np.allclose(aligned_gains(before, after, idx, k, fitted), 0.0, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.1, 3.0), st.floats(0.0, 0.9))
def test_placebo_noise_has_the_estimated_size_and_serial_correlation(seed, sigma, phi):
    """The noise a delay's placebo draws: standard deviation `sigma` from its first frame on (it starts stationary,
    not at the innovations' smaller size) and lag-1 correlation `phi`."""
    from identcheck.effects.time_offset import ar1_noise

    rng = np.random.default_rng(seed)
    e = ar1_noise(rng, (3000, 4, 3), sigma, phi)
    assert np.std(e) == pytest.approx(sigma, rel=0.1)
    assert np.sum(e[1:] * e[:-1]) / np.sum(e[:-1] ** 2) == pytest.approx(phi, abs=0.03)
    start = ar1_noise(rng, (2, 3000, 3), sigma, phi)[0]
    assert np.std(start) == pytest.approx(sigma, rel=0.06)


@pytest.mark.parametrize("seed", [0, 3])
def test_no_marker_of_a_still_root_is_named_late_for_re_aligning_correlated_noise(seed):
    """No delay, a still pelvis, AR(1) noise (φ 0.8, 0.9 mm): shifting one of its markers by a frame pairs each
    frame's noise with the next frame's, and the refit gains a spread of ±70 σ² about a small loss. The criterion
    alone (one parameter, ln 3N) let some such delay through (these seeds: a score above 0); none stands three
    standard deviations of what re-aligned noise gains clear of it (:meth:`TimeOffset.implausible`)."""
    from identcheck.bundle.hypothesis import score
    from identcheck.diagnose.workflow import start
    from identcheck.effects.base import Proposal
    from identcheck.effects.time_offset import TimeOffset, ar1_noise

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=1200, noise_mm=0.0, seed=seed, root_motion=False)
    xyz = sim.trial.as_array() + ar1_noise(np.random.default_rng(seed), sim.trial.as_array().shape, 0.9, 0.8)
    ctx, h = start(model, sim.trial.replace(xyz=xyz))
    eff, scores, reasons = TimeOffset(), [], []
    for m in model.segments[model.root].markers:
        c = list(h.chain.labels).index(m)
        for k in (-1, 1):
            prop = Proposal(eff.name, {"segment": model.root, "delay_ms": 10.0 * k, "markers": [m]}, 1.0,
                            {"segment": model.root, "columns": [c], "tau": k / 100.0, "from_rigidity": True})
            scores.append(score(ctx, eff.apply(ctx, h, prop), h))
            reasons.append(eff.implausible(prop))
    assert max(scores) > 0.0
    assert all(reasons)


@settings(max_examples=60, deadline=None)
@given(st.floats(-1e4, 1e5), st.floats(0.0, 1e3))
def test_a_delay_is_adopted_and_kept_by_one_rule(score, spread):
    """The forward gate (:meth:`TimeOffset.implausible`, on the score the delay's fit reached) and the backward
    check's (:meth:`TimeOffset.stands_out`, on what it gains given the other effects) are one rule: three spreads of
    what shifting the noise alone gains."""
    from identcheck.effects.base import Proposal
    from identcheck.effects.time_offset import REALIGN_Z, TimeOffset

    eff = TimeOffset()
    prop = Proposal(eff.name, {"segment": "s", "delay_ms": 10.0}, 1.0,
                    {"noise_sd": spread, "score": score})
    assert (eff.implausible(prop) == "") == eff.stands_out(prop, score) == (score > REALIGN_Z * spread)


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**16), st.floats(1.2, 3.8))
def test_a_delays_screen_then_its_full_fit_are_the_full_fit_alone(seed, frames):
    """The shank 1.2-3.8 frames late: a delay's screen (Newton until a step moves it under a tenth of a frame, charged
    one parameter) and then its full fit, which takes Newton up where the screen left it, give what the full fit gives
    alone, to the last bit, with no more refits in all."""
    from identcheck.bundle.hypothesis import Hypothesis
    from identcheck.effects.registry import EFFECTS

    ctx, h, cols, rate = _shank_late(seed, frames, 0.5)
    eff = EFFECTS["time_offset"]
    shank = [p for p in eff.propose(ctx, h) if p.where["segment"] == "shank" and "markers" not in p.where]
    alone, screened = shank[0], next(p for p in eff.propose(ctx, h) if p.where == shank[0].where)
    calls, refit = [], Hypothesis.refit

    def counted(self, *args, **kwargs):
        calls.append(1)
        return refit(self, *args, **kwargs)

    Hypothesis.refit = counted
    try:
        direct = eff.apply(ctx, h, alone)
        n_alone = len(calls)
        first = eff.screen(ctx, h, screened)
        n_screen = len(calls) - n_alone
        after = eff.apply(ctx, h, screened)
    finally:
        Hypothesis.refit = refit
    assert first.n_params() == h.n_params() + 1 and n_screen >= 1
    assert len(calls) - n_alone == n_alone         # the screen's Newton steps are not taken again
    assert alone.where == screened.where
    assert np.array_equal(direct.fit.pred, after.fit.pred, equal_nan=True) and direct.rss == after.rss
    assert direct.extra_params == after.extra_params and "newton" not in screened.payload


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 2**16), st.integers(1, 3), st.floats(0.2, 0.45), st.sampled_from([-1.0, 1.0]))
def test_a_delay_adopted_in_whole_frames_leaves_its_fraction_free_for_the_joints(seed, frames, fraction, side):
    """The shank late by a whole number of frames and a fraction (0.2-0.45 frame; 0.6 mm white noise), the delay
    adopted at the whole frame on either side: the joints are judged from a refit that fits the fraction (within
    0.1 frame of the truth, and reported as ``delay_ms_fitted``), and the knee's distances come within two
    half-widths of their intervals of those a fit to the data realigned by the true delay gives, a quarter of the way
    at most that the whole frame leaves them (there the knee moves by millimetres; the two realignments smooth the
    noise differently, so the two fits differ by about a standard error)."""
    import identcheck.effects.time_offset as time_offset
    from identcheck.diagnose.workflow import joint_report, marker_distances, start, with_choices_free
    from identcheck.effects.registry import EFFECTS

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=600, noise_mm=0.0, seed=seed)
    xyz = sim.trial.as_array().copy()
    cols = [sim.trial.labels.index(m) for m in model.segments["shank"].markers]
    rate = sim.trial.rate_hz
    lag = frames + fraction
    xyz[:, cols] = shifted(xyz[:, cols], rate, -lag / rate, extrapolate=True)
    xyz += np.random.default_rng(seed).normal(0, 0.6, xyz.shape)
    ctx, h = start(model, sim.trial.replace(xyz=xyz))
    eff = EFFECTS["time_offset"]

    def adopted_at(whole: float):
        prop = next(p for p in eff.propose(ctx, h) if p.where["segment"] == "shank" and "markers" not in p.where)
        prop.payload["tau"] = whole / rate
        steps, time_offset.NEWTON_STEPS, walk = time_offset.NEWTON_STEPS, 0, time_offset.best_whole_frame
        time_offset.best_whole_frame = lambda scored, start: (scored(start[0]), start[0])[1]   # kept at that frame
        try:
            return eff.apply(ctx, h, prop).converged()
        finally:
            time_offset.NEWTON_STEPS, time_offset.best_whole_frame = steps, walk

    whole = float(np.floor(lag) if side < 0 else np.ceil(lag))
    late = adopted_at(whole)
    assert late.effects[-1].where["delay_ms"] == round(1000 * whole / rate, 2)
    freed = with_choices_free(ctx, late)
    refined = whole - float(freed.fit.state.term_params[-1][0]) * rate
    assert abs(refined - lag) < 0.1
    assert freed.effects[-1].where["delay_ms_fitted"] == round(1000 * refined / rate, 2)
    data = xyz.copy()
    data[:, cols] = shifted(xyz[:, cols], rate, lag / rate)
    lost = ~np.isfinite(data).all(axis=2)
    aligned = h.refit_corrected(ctx, data, np.where(lost, 0.0, h.weights)).converged()
    ideal = {m: d for m, (d, _sd) in marker_distances(ctx, aligned)["knee"].items()}
    whole_frame = {m: d for m, (d, _sd) in marker_distances(ctx, late)["knee"].items()}
    knee = joint_report(ctx, freed)["knee"]
    off = {m: abs(knee["marker_distances"][m] - d) for m, d in ideal.items()}
    assert max(off.values()) < 0.25 * max(abs(whole_frame[m] - d) for m, d in ideal.items()), (off, whole_frame)
    for m, d in ideal.items():
        lo, hi = knee["marker_distances_ci95"][m]
        assert hi is not None and off[m] <= 2 * (hi - lo) / 2, (m, d, lo, hi)
