"""A gross error under serially correlated noise: the departure of a sample from its neighbours in time
(:func:`identcheck.effects.outliers.spike_residuals`) is the least-squares size of a one-frame error in AR(1) noise.
It moves by the error's full size at its frame and by −c times it beside, whatever the noise; on AR(1) noise alone
its variance is σ²(1 − φ²)/(1 + φ²), a fraction of the residual's, so an error the noise bound cannot tell from the
noise's own tail stands out of it (a 7 mm error at σ 1.3 mm, φ 0.75: 5 standard deviations of the residual, 10 of
the departure; named on held-out draw 41, trial_0040, which the residual alone left unnamed)."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.effects.outliers import beside_errors, spike_residuals


def _ar1(rng, n_frames: int, n_markers: int, phi: float, sigma: float) -> np.ndarray:
    e = rng.normal(0.0, sigma * np.sqrt(1 - phi ** 2), (n_frames, n_markers, 3))
    x = np.empty_like(e)
    x[0] = rng.normal(0.0, sigma, (n_markers, 3))
    for t in range(1, n_frames):
        x[t] = phi * x[t - 1] + e[t]
    return x


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.98), st.integers(3, 300), st.integers(1, 5),
       st.floats(-50.0, 50.0))
def test_an_error_moves_its_frame_by_its_size_and_its_neighbours_by_minus_c_times_it(seed, phi, n_frames, n_markers,
                                                                                     size):
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, n_frames, n_markers, phi, 1.0)
    seen = rng.random((n_frames, n_markers)) > 0.1
    t, m, k = rng.integers(1, n_frames - 1), rng.integers(n_markers), rng.integers(3)
    seen[t - 1:t + 2, m] = True
    hit = noise.copy()
    hit[t, m, k] += size
    before, has = spike_residuals(noise, seen, phi)
    after, has_after = spike_residuals(hit, seen, phi)
    assert np.array_equal(has, has_after)
    diff = np.where(np.isfinite(after), after - before, 0.0)
    c = phi / (1 + phi * phi)
    want = np.zeros_like(diff)
    want[t, m, k] = size
    for s in (t - 1, t + 1):
        if has[s, m]:
            want[s, m, k] = -c * size
    assert np.allclose(diff, want, atol=1e-9 * max(1.0, abs(size)))
    assert not has[~seen].any()                 # nothing for an unseen sample


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.95))
def test_on_ar1_noise_its_variance_is_the_formula(seed, phi):
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, 4000, 4, phi, 1.3)
    spike, has = spike_residuals(noise, np.ones(noise.shape[:2], bool), phi)
    want = 1.3 ** 2 * (1 - phi ** 2) / (1 + phi ** 2)
    assert abs(np.var(spike[has]) / want - 1.0) < 0.1
    assert np.var(spike[has]) <= np.var(noise) * 1.1      # never wider than the residual it comes from


def _beside(noise: np.ndarray, phi: float, bound: float) -> np.ndarray:
    """The adjusted departures (:func:`beside_errors`) of `noise` (F, M, 3), every sample seen, on the AR(1) formula's
    scale for unit noise."""
    seen = np.ones(noise.shape[:2], bool)
    spike, has = spike_residuals(noise, seen, phi)
    scale2 = (1 - phi ** 2) / (1 + phi ** 2)
    departure = np.where(has, np.sum(np.nan_to_num(spike) ** 2, axis=2), 0.0) / scale2
    return beside_errors(noise, seen, phi, departure, scale2, bound), departure


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.3, 0.95), st.floats(15.0, 60.0), st.floats(1.0, 3.0))
def test_beside_an_error_a_sample_is_judged_as_if_the_error_were_not_there(seed, phi, size, factor):
    """The neighbours of a gross error are judged without it: their statistic does not depend on the error's size
    (any size that makes it the larger), and what the error itself shows is unchanged."""
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, 200, 2, phi, 1.0)
    t, m = int(rng.integers(2, 198)), int(rng.integers(2))
    bound = 30.0
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    runs = []
    for s in (size, size * factor):
        hit = noise.copy()
        hit[t, m] += s * direction
        runs.append(_beside(hit, phi, bound))
    (a, dep_a), (b, dep_b) = runs
    assert a[t, m] == dep_a[t, m] and b[t, m] == dep_b[t, m]          # the error's own departure, as it was
    for s in (t - 1, t + 1):
        if dep_a[t, m] > max(dep_a[s, m], bound) and dep_b[t, m] > max(dep_b[s, m], bound):
            assert np.isclose(a[s, m], b[s, m], rtol=1e-9, atol=1e-9)
            other = s + (s - t)                                        # its other neighbour
            want = np.sum((noise[s, m] - phi * noise[other, m]) ** 2) / (1 - phi ** 2)
            if not (a[other, m] > max(a[s, m], bound)):
                assert np.isclose(a[s, m], want, rtol=1e-9, atol=1e-9)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.5, 0.9))
def test_beside_errors_the_statistic_is_chi2_3_again(seed, phi):
    """On AR(1) noise with errors of 10-20 σ every 20 frames, the neighbours' statistic has the mean of a χ²₃
    (3), where their departures from both sides had read c² s² / var above it."""
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, 20000, 1, phi, 1.0)
    at = np.arange(10, 20000 - 10, 20)
    direction = rng.normal(size=(len(at), 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    noise[at, 0] += rng.uniform(10.0, 20.0, (len(at), 1)) * direction
    adjusted, departure = _beside(noise, phi, 30.0)
    beside = np.concatenate([at - 1, at + 1])
    assert abs(np.mean(adjusted[beside, 0]) - 3.0) < 0.35
    assert np.mean(departure[beside, 0]) > 3.0 + 0.5 * np.mean((phi / (1 + phi ** 2)) ** 2 * 100
                                                              / ((1 - phi ** 2) / (1 + phi ** 2)))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.3, 0.95), st.floats(15.0, 40.0), st.floats(0.8, 1.25))
def test_two_errors_in_a_row_both_stand_out(seed, phi, size, ratio):
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, 100, 1, phi, 1.0)
    t = int(rng.integers(5, 94))
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    noise[t, 0] += size * direction
    noise[t + 1, 0] += size * ratio * rng.choice([-1.0, 1.0]) * direction
    adjusted, _ = _beside(noise, phi, 30.0)
    assert adjusted[t, 0] > 30.0 and adjusted[t + 1, 0] > 30.0


def _beside_by_search(residuals, seen, phi, departure, scale2, bound):
    """beside_errors written the plain way: the largest sample not yet taken, searched over every sample."""
    F, M = departure.shape
    out, taken = departure.astype(float), np.zeros((F, M), bool)
    r = np.where(seen[..., None], residuals, 0.0)
    while True:
        t, m = divmod(int(np.argmax(np.where(taken, -np.inf, out))), M)
        if taken[t, m] or not out[t, m] > bound:
            return out
        taken[t, m] = True
        for s in (t - 1, t + 1):
            if 0 <= s < F and not taken[s, m]:
                o = 2 * s - t
                ok = 0 <= o < F and seen[s, m] and seen[o, m] and not taken[o, m]
                out[s, m] = np.sum((r[s, m] - phi * r[o, m]) ** 2) / (scale2 * (1 + phi * phi)) if ok else 0.0


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.95), st.integers(2, 60), st.integers(1, 4), st.floats(0.0, 0.3))
def test_the_heap_takes_the_samples_a_plain_search_would(seed, phi, n_frames, n_markers, rate):
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, n_frames, n_markers, phi, 1.0)
    hit = rng.random((n_frames, n_markers)) < rate
    noise[hit] += rng.uniform(-15.0, 15.0, (int(hit.sum()), 3))
    seen = rng.random((n_frames, n_markers)) > 0.15
    spike, has = spike_residuals(noise, seen, phi)
    scale2 = max((1 - phi ** 2) / (1 + phi ** 2), 1e-3)
    departure = np.where(has, np.sum(np.nan_to_num(spike) ** 2, axis=2), 0.0) / scale2
    res = np.nan_to_num(np.where(seen[..., None], noise, np.nan))
    assert np.array_equal(beside_errors(res, seen, phi, departure, scale2, 20.0),
                          _beside_by_search(res, seen, phi, departure, scale2, 20.0))
