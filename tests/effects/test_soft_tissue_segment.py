"""Skin over a whole segment: every marker of the thigh moving on it its own way, with the hip's and the knee's
angles together (a bulge with their product). Before, ``soft_tissue`` proposed one marker, or the cluster moving as
one, with one joint's angles at a time; such a thigh was named ``spatial_distortion`` first, its 53 fields
explaining more in one step than any single marker's skin."""
from __future__ import annotations

import warnings
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from identcheck.diagnose import workflow
from identcheck.effects.injection import marker_column, normalised_angle, rotate, rotations
from identcheck.effects.registry import EFFECTS
from identcheck.effects.soft_tissue import drivers
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton
from identcheck.trial import Trial

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
LEG = EXAMPLES / "diagnose_leg.toml"


@pytest.mark.parametrize("name", ["diagnose_leg.toml", "leg.toml", "body16.toml", "real_walking2_legs.toml"])
def test_skin_is_driven_by_each_joint_of_its_segment_and_by_each_pair_of_them(name):
    """Each segment's skin: by each of its own joints, each pair of them, and each joint one segment further (a
    muscle crossing two joints), never by a joint further away."""
    chain = Skeleton.from_model(Model.from_toml(EXAMPLES / name))
    got = drivers(chain)
    assert len(got) == len(set(got))
    for seg in chain.seg_markers:
        own = [j for j in chain.joints if seg in (chain.parent[j], chain.child[j])]
        beside = {chain.parent[j] for j in own} | {chain.child[j] for j in own}
        near = [j for j in chain.joints if j not in own and {chain.parent[j], chain.child[j]} & beside]
        mine = {js for s, js in got if s == seg}
        assert mine == {(j,) for j in own} | set(combinations(own, 2)) | {(j,) for j in near}


def _thigh_skin(seed: int, size_mm: float, n_frames: int = 700, noise_mm: float = 0.5):
    """The leg with every thigh marker moving on the thigh by its own smooth function of hip flexion h and knee
    angle k (h, k, h·k, h², k², each times a random 3-vector), scaled so that the largest displacement is
    `size_mm`."""
    model = Model.from_toml(LEG)
    sim = simulate(model, n_frames=n_frames, noise_mm=noise_mm, seed=seed)
    rng = np.random.default_rng(seed)
    h = normalised_angle(sim.truth.joints["hip"], low=-1.0)
    k = normalised_angle(sim.truth.joints["knee"], low=-1.0)
    feats = np.column_stack([h, k, h * k, h * h, k * k])
    feats -= feats.mean(axis=0)
    moves = {m: feats @ rng.normal(size=(5, 3)) for m in model.segments["thigh"].markers}
    peak = max(np.linalg.norm(v, axis=1).max() for v in moves.values())
    clean = sim.clean.as_array()
    noise = sim.trial.as_array() - clean
    R = rotations(sim, "thigh")
    for m, v in moves.items():
        clean[:, marker_column(sim, m)] += rotate(R, v * size_mm / peak)
    return model, sim.trial.replace(xyz=clean + noise)


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), size=st.floats(4.0, 12.0))
def test_the_whole_thigh_is_the_strongest_skin_place_and_its_refit_reaches_the_noise(seed, size):
    model, trial = _thigh_skin(seed, size)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, h = workflow.start(model, trial.recentred()[0])
    eff = EFFECTS["soft_tissue"]
    first = eff.propose(ctx, h)[0]
    assert first.where["segment"] == "thigh"
    assert first.where["markers"] == list(model.segments["thigh"].markers)
    assert not first.where.get("together")
    after = eff.apply(ctx, h, first).polish()
    assert after.gap(ctx) <= 1.5 * after.floor(ctx)
    assert after.gap(ctx) < h.gap(ctx)


def test_diagnose_names_the_thighs_skin_in_one_step_and_no_distortion(tmp_path):
    model, trial = _thigh_skin(11, 8.0, n_frames=1200)
    path = tmp_path / "thigh_skin.trc"
    trial.to_file(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = workflow.diagnose(model, Trial.from_file(path)).to_dict()
    names = [e["name"] for e in rep["effects"]]
    assert names[0] == "soft_tissue" and "spatial_distortion" not in names
    assert rep["effects"][0]["where"]["segment"] == "thigh"
    assert set(rep["effects"][0]["where"]["markers"]) == set(model.segments["thigh"].markers)
    assert rep["gap_after"] <= 1.5 * rep["noise_floor"]
