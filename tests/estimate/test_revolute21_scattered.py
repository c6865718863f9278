"""The revolute (2,1) least squares also starts from random joints (:func:`scattered_seed`), since with noise every
slot of the closed form can lie in the basin of a wrong minimum; the random starts' short unbounded refinements are
brought back to r, ρ ≥ 0 and α in [0, π] by :func:`canonical`, which must not change the joint's meridian."""
import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.estimate import revolute21 as r21
from strategies import revolute21_samples


@given(st.lists(st.floats(-300, 300), min_size=5, max_size=5), st.integers(0, 2**16))
def test_canonical_constants_have_the_same_residuals(params, seed):
    params = np.array(params)
    params[2] = params[2] / 300 * 4 * np.pi                      # any angle, several turns either way
    canon = r21.canonical(params)
    assert canon[1] >= 0 and canon[4] >= 0 and 0 <= canon[2] <= np.pi
    samples = np.random.default_rng(seed).normal(scale=150.0, size=(40, 3))
    R, z = np.hypot(samples[:, 0], samples[:, 1]), samples[:, 2]
    np.testing.assert_allclose(r21.residuals(canon, R, z), r21.residuals(params, R, z), rtol=1e-7, atol=1e-6)


def _knee_like(seed: int, n: int = 300, noise: float = 0.5):
    """Noisy samples of a random joint flexing over part of a turn while the parent rolls about A1A2."""
    rng = np.random.default_rng(seed)
    truth = np.array([rng.uniform(-200, 200), rng.uniform(10, 200), rng.uniform(0.3, np.pi - 0.3),
                      rng.uniform(-200, 200), rng.uniform(30, 200)])
    beta = rng.uniform(-np.pi, np.pi) + rng.uniform(0.8, 2.0) * (0.5 + 0.5 * np.sin(np.linspace(0, 12, n)))
    theta = rng.uniform(-np.pi, np.pi) + rng.uniform(0.3, 1.5) * np.sin(np.linspace(0, 7, n) + 1)
    return truth, revolute21_samples(truth, theta, beta) + rng.normal(scale=noise, size=(n, 3))


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**20))
def test_the_fit_is_at_least_as_good_as_the_truth(seed):
    """The truth is one joint the least squares could return, so the best it returns must fit the samples about as
    well (within 5 % of RMS distance) or better."""
    truth, local = _knee_like(seed)
    R, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    at_truth = float(np.sqrt(np.mean(r21.residuals(truth, R, z) ** 2)))
    sols = r21.fit(local, max_nfev=100)
    assert sols and sols[0][1] <= 1.05 * at_truth


def test_a_scattered_start_finds_the_basin_the_closed_form_misses(monkeypatch):
    """Sample sets (seeds found by a search over 40, then fixed) on which every closed-form slot refines to a
    minimum three times the truth's RMS distance: with the scattered start the fit reaches the truth's."""
    for seed in (23, 39):
        truth, local = _knee_like(seed)
        R, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
        at_truth = float(np.sqrt(np.mean(r21.residuals(truth, R, z) ** 2)))
        assert r21.fit(local, max_nfev=100)[0][1] <= 1.05 * at_truth
        with monkeypatch.context() as m:
            m.setattr(r21, "scattered_seed", lambda *a, **k: None)
            assert r21.fit(local, max_nfev=100)[0][1] > 2 * at_truth
