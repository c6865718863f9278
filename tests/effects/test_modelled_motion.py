"""The motions with the angles an effect's terms fit are read from that effect's own terms: skin from its markers'
terms, a moving centre from its joint's term and its own linear part (a hinge's screw along its axis, a ball joint's
world terms), each as the RMS of the fitted offsets about their mean, never from another effect's terms or fields."""
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.model import Terms
from identcheck.effects.base import Proposal
from identcheck.effects.registry import EFFECTS


def _chain():
    return SimpleNamespace(parent={"hip": "pelvis", "knee": "thigh"}, child={"hip": "thigh", "knee": "shank"})


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), frames=st.integers(20, 200), k=st.integers(1, 6), hidden=st.floats(0, 0.6))
def test_each_effect_reads_its_own_terms(seed, frames, k, hidden):
    rng = np.random.default_rng(seed)
    skin_basis, other_basis, centre_basis = (rng.normal(size=(frames, k)) for _ in range(3))
    B_one, B_cluster, B_other, D = (rng.normal(0, 3, (k, 3)) for _ in range(4))
    linear = [rng.normal(size=(frames, 3)) for _ in range(2)]        # the translation's linear fields (parent frame)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    screw = linear[0] @ axis                          # what its apply made of a hinge's linear field (θ a): a screw
    linear[0] = np.outer(screw, axis)
    world_fields = [rng.normal(size=(frames, 2, 3))]    # what its apply put in the world terms for a ball joint's field
    other_world = rng.normal(size=(frames, 8, 3))                       # another effect's world term (a field)
    c_lin = rng.normal(size=2)
    terms = Terms(markers=[(3, skin_basis), (np.array([4, 5]), skin_basis), (6, other_basis)],
                  centres=[("knee", centre_basis)],
                  screws=[("knee", rng.normal(size=frames)), ("knee", screw)],
                  world=[(np.arange(8), other_world), (np.array([6, 7]), world_fields[0])])
    weights = (rng.uniform(size=(frames, 8)) >= hidden).astype(float)
    weights[0] = 1.0
    hyp = SimpleNamespace(chain=_chain(), terms=terms, weights=weights,
                          fit=SimpleNamespace(state=SimpleNamespace(
                              axis={"knee": axis}, term_params=[B_one, B_cluster, B_other, D]
                              + [np.array([7.0]), np.array([c_lin[0]]), np.array([9.0]), np.array([c_lin[1]])])))

    def rms(offsets, rows):                                # about the mean: a constant offset is no motion
        moved = offsets[rows] - offsets[rows].mean(axis=0)
        return float(np.sqrt(np.mean(np.sum(moved ** 2, axis=1))))

    skin = EFFECTS["soft_tissue"]
    one = skin.modelled_motion(Proposal("soft_tissue", {"segment": "thigh"}, 1.0,
                                        {"col": 3, "basis": skin_basis}), hyp)
    assert [m.segments for m in one] == [("thigh",)] and one[0].joint is None
    assert np.isclose(one[0].rms_mm, rms(skin_basis @ B_one, weights[:, 3] > 0))
    cluster = skin.modelled_motion(Proposal("soft_tissue", {"segment": "shank"}, 1.0,
                                            {"col": np.array([4, 5]), "basis": skin_basis}), hyp)
    assert len(cluster) == 1
    assert np.isclose(cluster[0].rms_mm, rms(skin_basis @ B_cluster, np.any(weights[:, [4, 5]] > 0, axis=1)))
    fresh = rng.normal(size=(frames, k))                   # a proposal whose terms the hypothesis does not hold
    assert skin.modelled_motion(Proposal("soft_tissue", {"segment": "thigh"}, 1.0, {"col": 3, "basis": fresh}),
                                hyp) == []
    moving = EFFECTS["joint_translation"].modelled_motion(
        Proposal("joint_translation", {"joint": "knee"}, 1.0,
                 {"joint": "knee", "basis": centre_basis, "linear": linear[1:], "screws": [screw],
                  "world_fields": [world_fields[0]]}), hyp)
    assert len(moving) == 1 and moving[0].joint == "knee" and moving[0].segments == ("thigh", "shank")
    centre_moves = centre_basis @ D + c_lin[0] * np.outer(screw, axis) + c_lin[1] * linear[1]
    assert np.isclose(moving[0].rms_mm, rms(centre_moves, np.ones(frames, bool)))
    quadratic_only = EFFECTS["joint_translation"].modelled_motion(
        Proposal("joint_translation", {"joint": "knee"}, 1.0, {"joint": "knee", "basis": centre_basis}), hyp)
    assert np.isclose(quadratic_only[0].rms_mm, rms(centre_basis @ D, np.ones(frames, bool)))
    assert moving[0].beside(hyp.chain, "knee") and not moving[0].beside(hyp.chain, "hip")
    assert one[0].beside(hyp.chain, "hip") and one[0].beside(hyp.chain, "knee")
    for name in ("marker_slip", "outliers", "spatial_distortion", "time_offset", "marker_swap", "extra_dof"):
        assert EFFECTS[name].modelled_motion(Proposal(name, {}, 1.0, {"basis": skin_basis, "col": 3}), hyp) == []
