"""A capture volume found distorted leaves every length uncertain by its unseen uniform scale: the distortion says
how large that is, the joints' intervals take it in, and a trial scaled along one axis is then covered."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import identcheck as ic
from identcheck.bundle.honest import NO_BOUND, Minimum, ci, with_scale_error
from identcheck.bundle.model import Terms
from identcheck.effects.base import Proposal
from identcheck.effects.registry import EFFECTS
from identcheck.effects.spatial_distortion import volume
from identcheck.io.model import Model
from identcheck.report.text import diagnose_text
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial

EXAMPLES = Path(__file__).parents[2] / "examples"

_distance = st.floats(5.0, 600.0)
_se = st.floats(0.01, 5.0)
_method = st.sampled_from(["profile", "bootstrap", "profile+bootstrap", "unbounded", "not_profiled"])


@settings(max_examples=60, deadline=None)
@given(per=st.dictionaries(st.sampled_from(["A", "B", "C", "D"]), st.tuples(_distance, _se, _method), min_size=1),
       rel=st.floats(1e-5, 0.02), open_top=st.booleans())
def test_scale_error_widens_every_bounded_interval_about_its_estimate_in_quadrature(per, rel, open_top):
    """Random distances, standard errors and intervals made by every method: each standard error becomes
    ``hypot(se, d · rel)``, each interval that claims a bound still holds the old one and is widened on each side
    by ``1.96 d · rel`` in quadrature (so a quadratic interval is the quadratic interval of the new error), its
    method marked ``+scale``; an interval that claims no bound is left as it was."""
    distances = {"j": {m: (d, se) for m, (d, se, _) in per.items()}}
    intervals = {"j": {}}
    for m, (d, se, how) in per.items():
        if how in NO_BOUND:
            intervals["j"][m] = ([0.0, None], how)
        else:
            lo, hi = max(d - 2.5 * se, 0.0), d + 1.5 * se
            intervals["j"][m] = ([lo, None if (open_top and how == "profile") else hi], how)
    m = Minimum(fit=None, cov=None, distances=distances, start=(), intervals=intervals)
    got = with_scale_error(m, rel)
    assert got.scale_sd == rel
    for k, (d, se, how) in per.items():
        assert got.distances["j"][k] == (d, pytest.approx(float(np.hypot(se, d * rel)), rel=1e-12))
        (lo, hi), new_how = got.intervals["j"][k]
        (lo0, hi0), _ = intervals["j"][k]
        if how in NO_BOUND:
            assert (lo, hi, new_how) == (lo0, hi0, how)
            continue
        assert new_how == how + "+scale"
        assert lo <= lo0 + 1e-3 and (hi is None) == (hi0 is None)
        assert lo == pytest.approx(max(d - np.hypot(d - lo0, 1.959964 * d * rel), 0.0), abs=1e-3)
        if hi is not None:
            assert hi >= hi0 - 1e-3
            assert hi == pytest.approx(d + np.hypot(hi0 - d, 1.959964 * d * rel), abs=1e-3)
    quad = ci({k: (d, se) for k, (d, se, _) in per.items()})
    widened = ci(got.distances["j"])
    assert all(widened[k][0] <= quad[k][0] and widened[k][1] >= quad[k][1] for k in per)


def test_no_scale_error_leaves_the_minimum_as_it_was():
    m = Minimum(fit=None, cov=None, distances={"j": {"A": (100.0, 0.3)}}, start=())
    assert with_scale_error(m, 0.0) is m


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), eps=st.floats(-0.02, 0.02).filter(lambda e: abs(e) > 1e-6),
       frames=st.integers(2, 40), markers=st.integers(3, 12), hidden=st.floats(0.0, 0.5))
def test_a_uniform_scale_about_the_volume_is_read_as_its_own_size(seed, eps, frames, markers, hidden):
    """A field that scales the volume by ε about its centre moves each point by ε times its distance from there: the
    distortion's scale uncertainty is |ε| times the points' spread about their mean over their spread about the
    volume's centre (|ε| when the two coincide), whatever the cloud and whichever samples were unseen; a uniform
    shift added changes nothing (the poses take it up); a field twice as large says twice as much. The field is read
    from the model's own terms (its fitted coefficients), never from another effect's or from fields the model does
    not hold."""
    rng = np.random.default_rng(seed)
    at = rng.uniform(-900, 900, (frames, markers, 3)) + rng.uniform(-2000, 2000, 3)
    at[rng.uniform(size=(frames, markers)) < hidden] = np.nan
    at[0, 0] = at[0, 0] if np.all(np.isfinite(at[0, 0])) else rng.uniform(-900, 900, 3)
    field = np.nan_to_num(at - volume(at)[0])              # the volume scaled about its centre, per unit of ε
    shift = np.broadcast_to(rng.normal(0, 1, 3), at.shape).copy()
    seen = np.all(np.isfinite(at), axis=-1)
    spread = np.sqrt(np.mean(np.sum((at[seen] - at[seen].mean(axis=0)) ** 2, axis=-1)))
    reach = np.sqrt(np.mean(np.sum((at[seen] - volume(at)[0]) ** 2, axis=-1)))
    cols = np.arange(markers)
    other = rng.normal(0, 1, at.shape)                       # another effect's world term: not the distortion's

    def fitted(scale, shifted_by):                           # a hypothesis holding the fields with these coefficients
        terms = Terms(world=[(cols, other), (cols, field), (cols, shift)])
        params = [np.array([7.0]), np.array([scale]), np.array([shifted_by])]
        return SimpleNamespace(terms=terms, fit=SimpleNamespace(state=SimpleNamespace(term_params=params)))

    eff = EFFECTS["spatial_distortion"]
    mine = Proposal("spatial_distortion", {}, 1.0, {"data": at, "fields": [field, shift]})
    one = eff.scale_sd(mine, fitted(eps, 0.0))
    two = eff.scale_sd(mine, fitted(2 * eps, 0.0))
    shifted = eff.scale_sd(mine, fitted(eps, 5.0))
    assert one == pytest.approx(abs(eps) * spread / reach, rel=1e-9)
    assert shifted == pytest.approx(one, rel=1e-9)
    assert two == pytest.approx(2 * one, rel=1e-12)
    assert eff.scale_sd(Proposal("spatial_distortion", {}, 1.0, {}), fitted(eps, 0.0)) == 0.0
    strange = Proposal("spatial_distortion", {}, 1.0, {"data": at, "fields": [field.copy()]})   # not the model's
    assert eff.scale_sd(strange, fitted(eps, 0.0)) == 0.0
    assert EFFECTS["marker_slip"].scale_sd(Proposal("marker_slip", {}, 1.0, {"data": at, "fields": [field]}),
                                           fitted(eps, 0.0)) == 0


@pytest.mark.slow
def test_a_volume_stretched_along_one_axis_is_named_and_its_joints_intervals_hold_the_true_lengths(tmp_path):
    """A leg recorded in a volume stretched by 0.8 % along its height (a wand-length error on one axis: a uniform
    part of 0.27 % that no rigid body shows): diagnose names the distortion, and every joint interval holds the true
    marker distance, each marked as taking the capture's scale in, and the text report says so."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=600, noise_mm=0.3, seed=11)
    xyz = sim.trial.as_array()
    centre = volume(xyz)[0]
    stretched = xyz.copy()
    stretched[..., 2] = centre[2] + 1.008 * (xyz[..., 2] - centre[2])
    path = tmp_path / "stretched.trc"
    Trial.from_array(stretched, sim.trial.labels, sim.trial.rate_hz).to_trc(path)
    diag = ic.diagnose(EXAMPLES / "diagnose_leg.toml", path)
    report = diag.to_dict()
    assert "the uncertainties include" in diagnose_text(diag)
    assert [e["name"] for e in report["effects"]][:1] == ["spatial_distortion"]
    for j, ans in report["joints"].items():
        assert ans["practical"]["scale_sd"] > 0.001
        for m, d in sim.truth.marker_distances(j).items():
            lo, hi = ans["marker_distances_ci95"][m]
            assert lo <= d and (hi is None or d <= hi), (j, m, d, lo, hi)
            assert ans["interval_method"][m].endswith("+scale")
