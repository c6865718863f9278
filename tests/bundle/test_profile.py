"""Profile-likelihood intervals: the spring holds the distance, the interval matches the quadratic one where
the likelihood is a parabola and holds the truth, and segments that are not posed by themselves are found."""
from __future__ import annotations

import time
import warnings
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.profile import OutOfTime, distance_penalty, profile_interval
from identcheck.bundle.uncertainty import covariance, distance_gradients
from identcheck.fit.whole_tree import posed_by_itself, skeleton_of
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate


HIP_33 = """
units = "mm"
[segments.pelvis]
markers = ["LASI", "RASI", "SACR"]
[segments.thigh_r]
markers = ["RGT", "RTHI", "RKNE"]
length_mm = 420
[joints.hip_r]
type = "spherical"
parent = "pelvis"
child = "thigh_r"
"""


def _hip33(tmp_path_factory):
    path = tmp_path_factory.mktemp("profile") / "hip33.toml"
    path.write_text(HIP_33)
    return Model.from_toml(path)


def _fit(model, seed, frames=150, noise=0.7):
    sim = simulate(model, n_frames=frames, noise_mm=noise, seed=seed)
    chain = skeleton_of(model, sim.trial)
    data = sim.trial.select(chain.labels).as_array()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_chain(chain, data, initial_state(chain, data), max_iter=200)
    return sim, chain, data, fit, covariance(fit, data)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10 ** 5), shift=st.floats(-8.0, 8.0))
def test_spring_holds_the_distance_where_asked(tmp_path_factory, seed, shift):
    """A random target near the estimate: the penalised fit's distance lands on it within 0.01 mm, and the
    data's RSS can only grow (the unconstrained fit is the minimum)."""
    model = _hip33(tmp_path_factory)
    _, chain, data, fit, cov = _fit(model, seed)
    P = len(cov.information)
    joint = chain.joints[0]
    marker, (d0, _) = next(iter(distance_gradients(chain, fit.state, P)[joint].items()))
    scale = cov.sigma_mm ** 2
    pen = distance_penalty(chain, joint, marker, d0 + shift, np.sqrt(1e4 / scale), P)
    held = fit_chain(chain, data, fit.state, max_iter=60, penalty=pen)
    d = distance_gradients(chain, held.state, P)[joint][marker][0]
    assert abs(d - (d0 + shift)) < 1e-2
    assert held.rss >= fit.rss - 1e-6 * fit.rss


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10 ** 5))
def test_profile_interval_matches_the_parabola_and_holds_the_truth(tmp_path_factory, seed):
    """A hip seen by three markers on each side: the likelihood is close to a parabola, so the profile
    interval agrees with d ± 1.96 SE within a third of its width, and it holds the simulator's truth or
    misses it by less than its own width (a 95 % interval may miss)."""
    model = _hip33(tmp_path_factory)
    sim, chain, data, fit, cov = _fit(model, seed, frames=120, noise=1.0)
    P = len(cov.information)
    joint = chain.joints[0]
    truth = sim.truth.marker_distances(joint)
    marker, (d0, g) = next(iter(distance_gradients(chain, fit.state, P)[joint].items()))
    se = cov.se(g)
    pi = profile_interval(fit, data, joint, marker, max(cov.sigma_mm, 0.01) ** 2 * max(cov.inflation(g), 1.0), se, P)
    assert pi.lo is not None and pi.hi is not None
    assert pi.lo < d0 < pi.hi
    wald = 2 * 1.96 * se
    assert abs((pi.hi - pi.lo) - wald) < wald / 3 + 0.05
    assert pi.lo - (pi.hi - pi.lo) < truth[marker] < pi.hi + (pi.hi - pi.lo)


def test_posed_by_itself_counts_markers_and_joint_points(examples):
    """Three pelvis markers pose the pelvis; one thigh marker plus the hip centre leave the thigh's roll free;
    one shank marker plus the knee's axis pose the shank."""
    model = Model.from_toml(examples / "sparse_leg.toml")
    sim = simulate(model, n_frames=20, noise_mm=0.0, seed=1)
    chain = skeleton_of(model, sim.trial)
    assert posed_by_itself(chain, "pelvis")
    assert not posed_by_itself(chain, "thigh_r")
    assert posed_by_itself(chain, "shank_r")


def test_profiles_left_over_by_the_budget_claim_no_bound(tmp_path_factory, monkeypatch):
    """When the profile-likelihood budget is spent, the distances it did not reach get [0, None] marked
    ``not_profiled`` (not ``unbounded``: nothing was learnt), and the joint is undetermined, saying why."""
    import identcheck.bundle.honest as honest

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, _ = _fit(model, 7)
    best = honest.minimum(fit, data)
    monkeypatch.setattr(honest, "TOLERANCE_MM", 0.0)           # every joint counts as wide: profiles are due
    monkeypatch.setattr(honest, "PROFILE_BUDGET_S", -1.0)      # ... and the budget is already spent
    joint = chain.joints[0]
    intervals = honest.honest_intervals(best, data, best.cov.sigma_mm ** 2)
    assert {how for _, how in intervals[joint].values()} == {"not_profiled"}
    assert all(iv == [0.0, None] for iv, _ in intervals[joint].values())
    answer = honest.joint_answer(replace(best, intervals=intervals), joint)
    assert answer["practical"]["verdict"] == "undetermined"
    assert "budget" in answer["practical"]["reason"]
    assert set(answer["interval_method"].values()) == {"not_profiled"}


def test_profiles_on_threads_equal_profiles_one_by_one(tmp_path_factory, monkeypatch):
    """The profile likelihoods run side by side on threads give the very intervals they give one at a time, and
    ``IDENTCHECK_THREADS`` sets how many threads (a bad value falls back to the default)."""
    import identcheck.bundle.honest as honest

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, _ = _fit(model, 11)
    best = honest.minimum(fit, data)
    monkeypatch.setattr(honest, "TOLERANCE_MM", 0.0)           # every joint counts as wide: profiles are due
    results = {}
    for threads in ("1", "3"):
        monkeypatch.setenv("IDENTCHECK_THREADS", threads)
        assert honest.profile_threads() == int(threads)
        results[threads] = honest.honest_intervals(best, data, best.cov.sigma_mm ** 2)
    assert {how for per in results["1"].values() for _, how in per.values()} == {"profile"}
    assert results["1"] == results["3"]
    monkeypatch.setenv("IDENTCHECK_THREADS", "many")
    assert 1 <= honest.profile_threads() <= 4


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10 ** 5), late_s=st.floats(0.0, 100.0))
def test_a_profile_past_its_deadline_stops(tmp_path_factory, seed, late_s):
    """A deadline already passed (by 0-100 s): the profile raises OutOfTime instead of walking a side, and one in
    the future changes nothing."""
    model = _hip33(tmp_path_factory)
    _, chain, data, fit, cov = _fit(model, seed)
    P = len(cov.information)
    joint = chain.joints[0]
    marker = next(iter(distance_gradients(chain, fit.state, P)[joint]))
    scale, se = cov.sigma_mm ** 2, 1.0                 # (the standard error only sizes the first step)
    with pytest.raises(OutOfTime):
        profile_interval(fit, data, joint, marker, scale, se, P, deadline=time.monotonic() - late_s)
    free = profile_interval(fit, data, joint, marker, scale, se, P)
    timed = profile_interval(fit, data, joint, marker, scale, se, P, deadline=time.monotonic() + 3600)
    assert (free.lo, free.hi, free.refits) == (timed.lo, timed.hi, timed.refits)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10 ** 5), off=st.tuples(*[st.floats(-40.0, 40.0)] * 3).filter(
    lambda v: np.linalg.norm(v) > 10.0))
def test_a_profile_about_no_minimum_stops_at_its_first_better_fit(tmp_path_factory, seed, off):
    """A fit stopped before its first iteration with the joint 10-70 mm from the minimum's is no minimum: the
    profile's first refit lands more than one χ² unit below it, the walk ends there (one refit) and says so;
    honest_intervals claims no bound for that fit without profiling at all; about the converged fit no refit beats
    the minimum."""
    from identcheck.bundle import honest

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, cov = _fit(model, seed)
    P = len(cov.information)
    joint = chain.joints[0]
    marker = next(iter(distance_gradients(chain, fit.state, P)[joint]))
    scale = cov.sigma_mm ** 2
    start = fit.state.copy()
    for side in (start.c_parent, start.c_child):       # the joint moved on both segments
        side[joint] = side[joint] + np.array(off)
    early = fit_chain(chain, data, start, max_iter=0)
    assert not early.converged and early.rss > fit.rss + 100 * scale
    pi = profile_interval(early, data, joint, marker, scale, 1.0, P)
    assert pi.better_fit and pi.refits == 1 and pi.lowest_rss < early.rss - scale
    assert (pi.lo, pi.hi) == (None, None)
    best = honest.minimum(early, data)
    called = []
    real = honest.profile_interval
    honest.profile_interval = lambda *a, **k: called.append(a) or real(*a, **k)
    try:
        out = honest.honest_intervals(best, data, scale)
    finally:
        honest.profile_interval = real
    assert not called
    assert all(how == "unbounded" and hi is None for per in out.values() for (_, hi), how in per.values())
    assert set(out) == set(chain.joints)
    se = cov.se(distance_gradients(chain, fit.state, P)[joint][marker][1])
    ok = profile_interval(fit, data, joint, marker, scale, se, P)
    assert not ok.better_fit and ok.lowest_rss >= fit.rss - scale


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10 ** 5), marker_index=st.integers(0, 5))
def test_the_bounds_are_where_the_converged_profile_crosses(tmp_path_factory, seed, marker_index):
    """Each bound of a profile interval is a point of the profile itself: the distance held there by a stiff spring
    and every other unknown refitted to convergence (as the profile was first computed) leaves the data's cost
    χ²₁(0.95) above the minimum, within 0.25 χ² (the walk interpolates between refits in the root of Δχ²)."""
    from identcheck.bundle.profile import PROFILE_CHI2

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, cov = _fit(model, seed, frames=120, noise=1.0)
    P = len(cov.information)
    joint = chain.joints[0]
    per = distance_gradients(chain, fit.state, P)[joint]
    marker = sorted(per)[marker_index % len(per)]
    scale = cov.sigma_mm ** 2
    pi = profile_interval(fit, data, joint, marker, scale, cov.se(per[marker][1]), P)
    assert pi.lo is not None and pi.hi is not None and not pi.better_fit
    for bound in (pi.lo, pi.hi):
        pen = distance_penalty(chain, joint, marker, bound, np.sqrt(1e4 / scale), P)
        held = fit_chain(chain, data, fit.state, max_iter=400, tol=1e-13, penalty=pen)
        assert abs(distance_gradients(chain, held.state, P)[joint][marker][0] - bound) < 1e-2
        assert abs((held.rss - fit.rss) / scale - PROFILE_CHI2) < 0.25


def test_a_refit_that_does_not_converge_bounds_nothing(tmp_path_factory, monkeypatch):
    """Refits stopped after one iteration overstate how far the cost rises (the profile is a minimum over every
    other unknown): such a side claims no bound (the lower one 0, the upper one open), never a narrow interval."""
    import identcheck.bundle.profile as profile

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, cov = _fit(model, 5, frames=120, noise=1.0)
    P = len(cov.information)
    joint = chain.joints[0]
    marker, (_, g) = next(iter(distance_gradients(chain, fit.state, P)[joint].items()))
    scale = cov.sigma_mm ** 2
    monkeypatch.setattr(profile, "MAX_ITER", 1)
    pi = profile.profile_interval(fit, data, joint, marker, scale, cov.se(g), P)
    assert (pi.lo, pi.hi) == (0.0, None)


def test_a_better_fit_met_by_one_profile_withdraws_every_profile_about_that_minimum(tmp_path_factory, monkeypatch):
    """Profiles all measure Δχ² from one minimum: when the first profile meets a fit better than it, every distance
    that would be profiled is unbounded, and the profiles not yet begun are not run (one thread: one call)."""
    import identcheck.bundle.honest as honest
    from identcheck.bundle.profile import ProfileInterval

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, _ = _fit(model, 13)
    best = honest.minimum(fit, data)
    monkeypatch.setattr(honest, "TOLERANCE_MM", 0.0)           # every joint counts as wide: profiles are due
    monkeypatch.setenv("IDENTCHECK_THREADS", "1")
    calls = []

    def better(*args, **kwargs):
        calls.append(args[3])
        return ProfileInterval(None, None, 1, fit.rss - 10 * best.cov.sigma_mm ** 2, better_fit=True)

    monkeypatch.setattr(honest, "profile_interval", better)
    out = honest.honest_intervals(best, data, best.cov.sigma_mm ** 2)
    joint = chain.joints[0]
    assert len(calls) == 1 and len(out[joint]) > 1
    assert all(iv == [0.0, None] and how == "unbounded" for iv, how in out[joint].values())


def _one_dimensional(monkeypatch, profile, d0=100.0, scale=1.0):
    """The profile walk on a problem with one unknown, the distance itself, whose cost above the minimum is
    `profile(d − d0)` χ² units: each refit rests exactly where the cost plus the spring is least (a fine grid and
    a golden-section polish), as a converged refit would. Returns a stand-in minimum for :func:`profile_interval`."""
    from types import SimpleNamespace

    import identcheck.bundle.profile as walk

    def rest(state, penalty):
        target, weight = penalty
        kappa = weight ** 2 / scale
        total = lambda d: profile(d - d0) + kappa * (d - target) ** 2     # noqa: E731
        grid = np.linspace(0.0, 3 * d0 + abs(target), 20001)
        d = grid[np.argmin(total(grid))]
        lo, hi = max(d - 1e-2 * d0, 0.0), d + 1e-2 * d0
        g = (np.sqrt(5) - 1) / 2
        for _ in range(80):
            a, b = hi - g * (hi - lo), lo + g * (hi - lo)
            lo, hi = (lo, b) if total(a) < total(b) else (a, hi)
        return (lo + hi) / 2

    def fit_chain(chain, data, state, terms=None, weights=None, max_iter=0, tol=0.0, penalty=None, deadline=None):
        d = rest(state, penalty)
        return SimpleNamespace(state=d, rss=scale * float(profile(d - d0)), converged=True)

    monkeypatch.setattr(walk, "fit_chain", fit_chain)
    monkeypatch.setattr(walk, "distance_penalty", lambda chain, j, m, target, weight, n: (target, weight))
    monkeypatch.setattr(walk, "distance_gradients", lambda chain, state, n: {"j": {"m": (state, None)}})
    return SimpleNamespace(chain=None, state=d0, rss=0.0, terms=None)


@settings(max_examples=60, deadline=None)
@given(power=st.sampled_from([2.0, 3.0, 4.0, 6.0]), widths=st.tuples(st.floats(0.5, 40.0), st.floats(0.5, 40.0)),
       se_factor=st.floats(0.05, 20.0), wall=st.booleans())
def test_the_walk_finds_the_bound_of_profiles_of_any_steepness(power, widths, se_factor, wall):
    """Profiles |x/w|^p on either side (p = 2 a parabola, up to 6), or nearly flat up to a wall, with the standard
    error that sizes the first step off by up to 20 times either way: each side's bound is where Δχ² reaches
    χ²₁(0.95) less 0.6 χ² at most (never much inside the interval the profile gives) and 2 χ² beyond it at most
    (a walk out of points keeps its nearest point beyond the bound), never a side left open or at 0 that closes
    within the walk's span (a profile steeper than its local parabola had held the walk at one place and returned
    [0, None])."""
    from identcheck.bundle.profile import PROFILE_CHI2

    def profile(x):
        u = np.abs(x) / np.where(np.asarray(x) < 0, widths[0], widths[1])
        if wall:                                     # a slope of 0.5 χ² a width, then a wall
            return 0.5 * u + np.maximum(u - 3.0, 0.0) ** 2 * 50.0
        return u ** power

    d0 = 150.0
    with pytest.MonkeyPatch.context() as monkeypatch:
        best = _one_dimensional(monkeypatch, profile, d0=d0)
        pi = profile_interval(best, None, "j", "m", 1.0, se_factor * min(widths), 1)
    assert pi.lo is not None and pi.hi is not None and pi.lo > 0.0
    for bound in (pi.lo, pi.hi):
        assert PROFILE_CHI2 - 0.6 < profile(bound - d0) < PROFILE_CHI2 + 2.0, (bound, profile(bound - d0))


def test_a_better_fit_on_another_thread_withdraws_the_profiles_of_that_joint_already_made(tmp_path_factory,
                                                                                          monkeypatch):
    """Two threads: the first profile of the joint gives an interval, the second meets a better fit; when both are in,
    every profiled distance of the joint is unbounded, the one finished first included."""
    import threading as th

    import identcheck.bundle.honest as honest
    from identcheck.bundle.profile import ProfileInterval

    model = _hip33(tmp_path_factory)
    _, chain, data, fit, _ = _fit(model, 17)
    best = honest.minimum(fit, data)
    monkeypatch.setattr(honest, "TOLERANCE_MM", 0.0)           # every joint counts as wide: profiles are due
    monkeypatch.setenv("IDENTCHECK_THREADS", "2")
    first_done = th.Event()
    order = []

    def profile(fit_, data_, joint, marker, *args, **kwargs):
        if not order:
            order.append(marker)
            first_done.set()
            return ProfileInterval(1.0, 2.0, 1, fit.rss)
        first_done.wait(10.0)
        order.append(marker)
        return ProfileInterval(None, None, 1, fit.rss - 10 * best.cov.sigma_mm ** 2, better_fit=True)

    monkeypatch.setattr(honest, "profile_interval", profile)
    out = honest.honest_intervals(best, data, best.cov.sigma_mm ** 2)
    joint = chain.joints[0]
    assert len(order) >= 2
    assert all(iv == [0.0, None] and how == "unbounded" for iv, how in out[joint].values())


@settings(max_examples=40, deadline=None)
@example(level=3.24, rise=10.8, start=185.8, width=34.5, power=1.0, skew=1.0, se=0.131)   # found by review
@example(level=2.93, rise=5.7, start=148.0, width=0.7, power=2.0, skew=0.75, se=0.30)
@given(level=st.floats(2.0, 3.8), rise=st.floats(1.0, 30.0), start=st.floats(5.0, 200.0), width=st.floats(0.5, 40.0),
       power=st.sampled_from([1.0, 2.0, 4.0]), skew=st.floats(0.3, 3.0), se=st.floats(0.1, 100.0))
def test_no_bound_lies_inside_a_profile_that_levels_off_and_rises_again(level, rise, start, width, power, skew, se):
    """Profiles that rise to a level below χ²₁(0.95), stay there, and rise again beyond it (a plateau, where two
    points both near the bound can lie far apart): a bound may be wide or open, never more than 0.6 χ² inside the
    profile's (the line through two such points had closed one 53 mm inside, at Δχ² 3.0)."""
    from identcheck.bundle.profile import PROFILE_CHI2

    def profile(x):
        u = np.where(np.asarray(x) < 0, -np.asarray(x) * skew, np.asarray(x))
        return level * (1 - np.exp(-u / rise)) + (np.maximum(u - start, 0.0) / width) ** power

    d0 = 300.0
    with pytest.MonkeyPatch.context() as monkeypatch:
        best = _one_dimensional(monkeypatch, profile, d0=d0)
        pi = profile_interval(best, None, "j", "m", 1.0, se, 1)
    for bound in (pi.lo, pi.hi):
        if bound is not None and bound != 0.0:
            assert profile(bound - d0) > PROFILE_CHI2 - 0.6, (bound, profile(bound - d0))
