"""benchmarks/bench_detection_limits.py: the size its logistic fit calls the 90 % limit is where the fitted chance is
90 %, and a fit to draws from a known curve finds that curve's limit."""
import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.special import expit

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
import bench_detection_limits as bench  # noqa: E402

coef = st.tuples(st.floats(-5, 5), st.floats(0.5, 6), st.floats(-6, 0), st.floats(0, 3), st.floats(-2, 0))


@given(coef, st.floats(0.2, 2.0), st.integers(300, 4000), st.sampled_from([0.0, 1.0]), st.floats(0.5, 0.99))
def test_the_limit_is_where_the_fitted_chance_reaches_the_rate(beta, sigma, frames, ar1, rate):
    beta = np.array(beta)
    size = bench.limit_size(beta, sigma, frames, ar1, rate)
    p = float(expit(bench.design(size, sigma, frames, ar1) @ beta))
    assert abs(p - rate) < 1e-9


def test_a_curve_that_falls_with_size_has_no_limit():
    assert bench.limit_size(np.array([0.0, -1.0, 0.0, 0.0, 0.0]), 1.0, 1000, 0.0) is None


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.floats(1.5, 4.0), st.floats(0.2, 5.0))
def test_the_fit_recovers_a_known_curves_limit(seed, slope, true_limit):
    """Draws from a logistic curve of the size with the visible-χ² dependence on noise and length (slopes b, -b,
    b/2): the fitted limit at a grid point is within a factor 1.6 of the true one (2 000 trials)."""
    rng = np.random.default_rng(seed)
    n = 2000
    sigma = np.exp(rng.uniform(np.log(0.3), np.log(1.5), n))
    frames = np.exp(rng.uniform(np.log(500), np.log(3000), n))
    ar1 = rng.integers(0, 2, n).astype(float)
    # choose the intercept so the 90 % point at sigma 1, 1000 frames, white noise is `true_limit`
    b = np.array([0.0, slope, -slope, slope / 2, -1.0])
    b[0] = np.log(9.0) - bench.design(true_limit, 1.0, 1000, 0.0) @ b
    size = true_limit * np.exp(rng.uniform(-3, 3, n))
    y = (rng.random(n) < expit(bench.design(size, sigma, frames, ar1) @ b)).astype(float)
    fitted = bench.fit_logistic(bench.design(size, sigma, frames, ar1), y)
    est = bench.limit_size(fitted, 1.0, 1000, 0.0)
    assert est is not None and 1 / 1.6 < est / true_limit < 1.6
