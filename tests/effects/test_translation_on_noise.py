"""A translating joint is not read into noise: its fields are built from smoothed joint angles (the fitted angles
carry the noise of the frames they are fitted to), and its detector's strength is what the refit gains, to first
order (a score test), not a regression of one segment's residual that the rigid refit has mostly absorbed."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from identcheck.bundle.hypothesis import DRIVING_SMOOTHING_S, smoothed_in_time
from identcheck.diagnose.workflow import score, start
from identcheck.effects.registry import EFFECTS, inject_effect
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial

MODEL = Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml"


@lru_cache(maxsize=None)
def _model() -> Model:
    return Model.from_toml(MODEL)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), sigma=st.floats(0.2, 2.0), rate=st.sampled_from([50.0, 100.0, 200.0]))
def test_smoothing_takes_out_noise_and_keeps_slow_motion(seed, sigma, rate):
    rng = np.random.default_rng(seed)
    t = np.arange(int(15 * rate)) / rate
    motion = sum(rng.uniform(5, 20) * np.sin(2 * np.pi * f * t + rng.uniform(0, 6)) for f in rng.uniform(0.3, 1.0, 3))
    noisy = motion + rng.normal(0, sigma, t.shape)
    gap = rng.integers(0, len(t) - 30)
    noisy[gap:gap + 20] = np.nan
    out = smoothed_in_time(noisy[:, None], DRIVING_SMOOTHING_S * rate)[:, 0]
    assert np.array_equal(np.isnan(out), np.isnan(noisy))             # a gap stays a gap, nothing else is lost
    inner = np.isfinite(out) & (t > 0.3) & (t < t[-1] - 0.3)
    inner[max(gap - 15, 0):gap + 35] = False
    err = out[inner] - motion[inner]
    assert np.sqrt(np.mean(err ** 2)) < 0.5 * sigma + 0.1 * np.std(motion)
    smooth_only = smoothed_in_time(motion[:, None], DRIVING_SMOOTHING_S * rate)[:, 0]
    assert np.max(np.abs(smooth_only - motion)[inner]) < 0.08 * np.ptp(motion)


def _hip_translation(trial):
    model = _model()
    ctx, h = start(model, trial.recentred()[0])
    h = h.polish(60)
    eff = EFFECTS["joint_translation"]
    (prop,) = [p for p in eff.propose(ctx, h) if p.where["joint"] == "hip"]
    return prop, score(ctx, eff.apply(ctx, h, prop).polish(30), h)


@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 10_000))
@example(seed=1)
@example(seed=3)
def test_a_hip_that_only_flexed_does_not_gain_a_translation_from_noise(seed):
    """Rigid data, a hip turned about one axis only, white noise: the other two components of its fitted rotation are
    noise, and translations linear in them had been fitted to it (seeds 1 and 3 gained 1 454 and 1 377 criterion
    units with the fitted angles)."""
    rng = np.random.default_rng(seed + 17)
    sim = simulate(_model(), n_frames=1500, seed=seed, rom_deg=40.0, n_axes=1)
    clean = sim.clean.as_array()
    trial = Trial(clean + rng.normal(scale=1.0, size=clean.shape), sim.clean.labels, sim.clean.rate_hz)
    _, gained = _hip_translation(trial)
    assert gained < 0.0


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_the_detector_strength_is_what_the_refit_gains(seed):
    """A joint translated with its angle (the simulator's even profile, 8–15 mm), white noise: the score test's
    estimate agrees with the fitted gain to within a third of it, and both find it."""
    sim = inject_effect(simulate(_model(), n_frames=1000, seed=seed, rom_deg=40.0, noise_mm=0.8), "joint_translation",
                        seed)
    joint = sim.settings["effect"]["where"]["joint"]
    model = _model()
    ctx, h = start(model, sim.trial.recentred()[0])
    eff = EFFECTS["joint_translation"]
    (prop,) = [p for p in eff.propose(ctx, h) if p.where["joint"] == joint]
    gained = score(ctx, eff.apply(ctx, h, prop).polish(30), h)
    assert gained > 50.0
    assert prop.strength == pytest.approx(gained, rel=0.35)
