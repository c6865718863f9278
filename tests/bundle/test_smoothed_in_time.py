"""The driving angles' smoothing leaves each frame's own sample out of its average: a function of a fitted angle
built at a frame carries none of that frame's measurement noise."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.hypothesis import smoothed_in_time


@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), width=st.floats(0.5, 12.0), n=st.integers(5, 400), cols=st.integers(1, 3))
def test_a_frames_smoothed_value_does_not_depend_on_its_own_sample(seed, width, n, cols):
    """Changing one frame's sample changes its neighbours' smoothed values, never its own (where it has a finite
    neighbour within the cut, four widths; at the ends too, where padding by the nearest sample would repeat it), and
    gaps stay gaps."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=(n, cols)), axis=0)
    x[rng.random(n) < 0.1] = np.nan
    t = int(rng.integers(0, n))
    y = x.copy()
    if np.isfinite(y[t]).all():
        y[t] += rng.normal(scale=100.0, size=cols)
    a, b = smoothed_in_time(x, width), smoothed_in_time(y, width)
    assert np.array_equal(np.isnan(a), np.isnan(x))
    reach = max(int(4.0 * width + 0.5), 1)
    lo, hi = max(t - reach, 0), min(t + reach + 1, n)
    if np.isfinite(x[lo:hi, 0]).sum() - np.isfinite(x[t, 0]) > 0 and np.isfinite(x[t]).all():   # a neighbour
        assert np.allclose(a[t], b[t], rtol=0, atol=1e-9 * (1 + np.nanmax(np.abs(x))))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), sigma=st.floats(0.1, 3.0))
def test_white_noise_in_the_angles_has_no_share_in_their_own_frames_smoothed_values(seed, sigma):
    """Smoothed white noise keeps no correlation with the same frame's noise (4 000 frames: the sample correlation,
    whose spread is about 1.4/√F here, within 8/√F of zero), where a Gaussian mean with its centre in keeps 0.38."""
    rng = np.random.default_rng(seed)
    e = rng.normal(scale=sigma, size=(4000, 1))
    s = smoothed_in_time(e, 4.0)
    r = np.corrcoef(e[:, 0], s[:, 0])[0, 1]
    assert abs(r) < 8 / np.sqrt(len(e))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), width=st.floats(0.5, 10.0), n=st.integers(3, 300))
def test_a_quadratic_in_time_is_kept_exactly(seed, width, n):
    """Each frame's value is that of a quadratic fitted to its neighbours, so a quadratic (and a line, and a constant)
    comes back as it went in at every frame whose neighbours within the cut are all seen (near the ends and gaps,
    where the quadratic would pass more noise than one sample, a line or a mean is fitted instead): a smooth motion
    loses nothing of its peaks to the smoothing."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    x = (rng.normal() + rng.normal() * t + rng.normal() * t ** 2 / n)[:, None] * rng.normal(size=2)
    x[rng.random(n) < 0.05] = np.nan
    out = smoothed_in_time(x, width)
    finite = np.isfinite(x)
    assert np.array_equal(np.isfinite(out), finite)
    reach = max(int(4.0 * width + 0.5), 1)
    seen = finite[:, 0]
    both = np.array([reach <= f < n - reach and seen[f - reach:f + reach + 1].all() for f in range(n)])
    assert np.allclose(out[both], x[both], rtol=1e-6, atol=1e-6 * (1 + np.nanmax(np.abs(x))))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), width=st.floats(0.5, 8.0), n=st.integers(2, 120))
def test_no_frame_carries_more_noise_than_one_sample(seed, width, n):
    """The smoothing is linear in the samples: each frame's value is a weighted sum of its neighbours', and the weights'
    root sum of squares (the white noise it passes, relative to one sample's) is at most 1 at every frame, ends and gap
    edges included (a quadratic fitted to neighbours on one side extrapolates: up to 275 beyond a long gap)."""
    rng = np.random.default_rng(seed)
    seen = rng.random(n) > rng.uniform(0.0, 0.6)
    weights = np.zeros((n, n))
    for j in np.flatnonzero(seen):
        unit = np.where(seen, 0.0, np.nan)
        unit[j] = 1.0
        weights[:, j] = np.nan_to_num(smoothed_in_time(unit, width))
    gain = np.sqrt(np.sum(weights ** 2, axis=1))[seen]
    assert np.all(gain <= 1.0 + 1e-9)
