"""Gross errors that last a few frames at one offset (a ghost, a camera's ray dropped and back), each sample too
small to fail the noise bound: found together as brief excursions that return, modelled as an offset over each run;
a lasting change (a slip) and smooth misfit are not such excursions."""
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.special import chdtri

import identcheck as ic
from identcheck.effects.outliers import excursions
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")
F, M, MAX_LEN = 1000, 6, 5


def _bound(n_samples: int) -> float:
    return float(chdtri(3, 0.005 / (n_samples * (MAX_LEN - 1))))


def _unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.floats(0.3, 1.5))
def test_bursts_beyond_the_bound_together_are_found_where_they_are(seed, n_bursts, sigma):
    """White noise on 6 markers, 1-6 bursts of 2-5 frames, each sized so that its departure from the frames either
    side is 2.5 times the trial-wide bound in expectation (6-8 σ): every burst is found on its marker, within a
    frame of its span."""
    rng = np.random.default_rng(seed)
    res = rng.normal(0, sigma, (F, M, 3))
    bound = _bound(F * M)
    truth = []
    for k in range(n_bursts):
        length = int(rng.integers(2, 6))
        t = 50 + k * 150 + int(rng.integers(0, 80))
        c = int(rng.integers(M))
        size = sigma * np.sqrt(2.5 * bound * (1 / length + 1 / 5))
        res[t:t + length, c] += size * _unit(rng)
        truth.append((c, t, length))
    found = excursions(res, np.ones((F, M), dtype=bool), MAX_LEN, bound)
    for c, t, length in truth:
        assert any(fc == c and abs(ft - t) <= 1 and abs(ft + fl - t - length) <= 1 for _, fc, ft, fl in found), \
            (truth, [(c, t, n) for _, c, t, n in found])


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.3, 1.5), st.floats(5.0, 30.0), st.floats(1.0, 5.0))
def test_a_lasting_step_and_smooth_misfit_are_no_excursion(seed, sigma, step_sigmas, wave_sigmas):
    """A marker stepping by 5-30 σ and staying (a slip), and another moving smoothly by 1-5 σ (skin with the
    angles, a 0.5-2 Hz wave), in white noise: no excursion is found on either."""
    rng = np.random.default_rng(seed)
    res = rng.normal(0, sigma, (F, M, 3))
    res[int(rng.integers(100, F - 100)):, 0] += step_sigmas * sigma * _unit(rng)
    t = np.arange(F) / 100.0
    res[:, 1] += wave_sigmas * sigma * np.sin(2 * np.pi * rng.uniform(0.5, 2.0) * t)[:, None] * _unit(rng)
    found = excursions(res, np.ones((F, M), dtype=bool), MAX_LEN, _bound(F * M))
    assert not [f for f in found if f[1] in (0, 1)], found


def test_diagnose_names_bursts_in_correlated_noise_that_no_sample_shows():
    """The leg with AR(1) noise (lag-1 coefficient 0.75, 0.8 mm), twelve bursts of 2-5 frames at 6-8 mm on random
    markers: named outliers first, as bursts (modelled as offsets, scoring 1 166 where setting samples aside one by
    one scored 439), on the bursts' markers, and the gap closed to within 1.1 times the noise floor."""
    rng = np.random.default_rng(11)
    sim = simulate(MODEL, n_frames=1200, noise_mm=0.0, seed=11)
    xyz = sim.trial.as_array().copy()
    phi, sigma = 0.75, 0.8
    e = np.zeros_like(xyz)
    e[0] = rng.normal(0, sigma, xyz.shape[1:])
    for f in range(1, len(xyz)):
        e[f] = phi * e[f - 1] + np.sqrt(1 - phi ** 2) * rng.normal(0, sigma, xyz.shape[1:])
    xyz += e
    hit = set()
    for k in range(12):
        t, length, c = 40 + 95 * k, int(rng.integers(2, 6)), int(rng.integers(xyz.shape[1]))
        xyz[t:t + length, c] += rng.uniform(6.0, 8.0) * _unit(rng)
        hit.add(sim.trial.labels[c])
    d = ic.diagnose(MODEL, sim.trial.replace(xyz=xyz)).to_dict()
    first = d["effects"][0]
    assert first["name"] == "outliers" and first["where"].get("bursts")
    assert set(first["where"]["markers"]) <= hit
    assert d["gap_after"] <= 1.1 * d["noise_floor"]


def test_pure_noise_shows_no_burst_and_short_trials_do_not_break_the_search():
    """White and AR(1) noise (φ 0.8) alone, 40 trials each of 6 markers x 1000 frames: at most 2 bursts in all (the
    bound allows 0.5 % a trial); trials of 3-30 frames, shorter than a run and its sides, give none and no error."""
    found = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        white = rng.normal(0, 1.0, (F, M, 3))
        ar = np.zeros((F, M, 3))
        ar[0] = rng.normal(0, 1.0, (M, 3))
        for f in range(1, F):
            ar[f] = 0.8 * ar[f - 1] + 0.6 * rng.normal(0, 1.0, (M, 3))
        for res in (white, ar):
            found += len(excursions(res, np.ones((F, M), dtype=bool), MAX_LEN, _bound(F * M)))
    assert found <= 2
    for n in (3, 10, 14, 30):
        res = np.random.default_rng(n).normal(0, 1.0, (n, M, 3))
        assert excursions(res, np.ones((n, M), dtype=bool), 15, _bound(n * M)) == [] or n >= 30
