"""Label swaps that begin inside an occlusion gap: labelling software often re-attaches the wrong trajectory when a
marker comes back, so the frames where the labels change over are the ones no camera saw. The distances then show
the swap from its first frame only through the one marker seen (:func:`swap_costs`), and the trajectories show it as
one label going on where the other was last seen (:func:`exchanges`). ``diagnose`` named such swaps (a thigh and a
shank marker, a shank's two anatomical markers, two pelvis markers) as skin motion or a hip translation."""
import tomllib

import numpy as np
from hypothesis import assume, given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.estimate.labels import LOOKBACK, MIN_RUN, detect, exchanges, screen
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton
from identcheck.trial import Trial
from tests.swapped_trials import assert_swap_named_first

MODEL = """
units = "mm"
[segments.upper]
markers = ["A1", "A2", "A3", "A4"]
[segments.lower]
markers = ["B1", "B2", "B3"]
[joints.j]
type = "spherical"
parent = "upper"
child = "lower"
"""
EXAMPLES = __import__("pathlib").Path(__file__).resolve().parents[2] / "examples"


def _local(rng, n: int) -> np.ndarray:
    """`n` marker places on a body, at least 40 mm apart, in a box of ±120 mm."""
    pts = []
    while len(pts) < n:
        p = rng.uniform(-120, 120, 3)
        if all(np.linalg.norm(p - q) >= 40 for q in pts):
            pts.append(p)
    return np.array(pts)


def _two_bodies(rng, n_frames: int, noise: float) -> np.ndarray:
    """Markers A1-A4 and B1-B3 of two bodies 400 mm apart, each turning smoothly (≤ 3 deg per frame) and moving up to
    0.5 m/s, (F, 7, 3)."""
    t = np.arange(n_frames) / 100.0
    parts = []
    for n, offset in ((4, 0.0), (3, 400.0)):
        freq, amp, phase = rng.uniform(0.2, 1.0, 3), rng.uniform(0.2, 0.8, 3), rng.uniform(0, 2 * np.pi, 3)
        R = Rotation.from_rotvec(amp * np.sin(2 * np.pi * freq * t[:, None] + phase)).as_matrix()
        parts.append(np.einsum("fij,mj->fmi", R, _local(rng, n)) + np.array([0.0, 0.0, offset]))
    pos = 500.0 * np.sin(rng.uniform(0.2, 1.0) * t)[:, None] * rng.normal(size=3) / np.sqrt(3)
    return np.concatenate(parts, axis=1) + pos[:, None] + rng.normal(0, noise, (n_frames, 7, 3))


def _swapped_in_gap(xyz, i, j, span, before, after):
    """Marker i hidden from `before` frames before the span's start to `after` frames into it, then labels i and j
    exchanged over the span: the labels change over while i is not seen."""
    a, b = span
    out = xyz.copy()
    out[a - before:a + after, i] = np.nan
    out[a:b + 1, [i, j]] = out[a:b + 1, [j, i]]
    return out


CHAIN = Skeleton.from_model(Model.from_dict(tomllib.loads(MODEL)))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), start=st.integers(30, 300), length=st.integers(20, 300),
       before=st.integers(0, 8), after=st.integers(1, 8), noise=st.floats(0.1, 1.5), same=st.booleans())
def test_a_swap_beginning_in_a_gap_is_read_from_its_first_frame(seed, start, length, before, after, noise, same):
    rng = np.random.default_rng(seed)
    i, j = (0, 1) if same else (0, 5)                       # A1 with A2, or A1 with B2 on the other body
    span = (start, start + length - 1)
    xyz = _swapped_in_gap(_two_bodies(rng, 700, noise), i, j, span, before, after)
    assert [(d["cols"], d["span"]) for d in exchanges(xyz, CHAIN)] == [((i, j), span)]
    if not same:       # across bodies the distances show it too, from the first frame, where only i's label is seen
        first = detect(xyz, CHAIN, noise, xyz.size)[0]
        assert (first["cols"], first["span"]) == ((i, j), span)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), start=st.integers(40, 300), length=st.integers(20, 150),
       before=st.integers(0, 20), after=st.integers(1, 20), noise=st.floats(0.1, 1.5), same=st.booleans())
def test_a_swap_beginning_in_a_long_gap_of_both_is_bounded_by_it(seed, start, length, before, after, noise, same):
    """Both markers hidden for longer than a step can be read across: the change is placed where they are seen again,
    which exchanges the same samples as the true span (hidden frames hold nothing to exchange)."""
    assume(before + after > LOOKBACK and length - after >= MIN_RUN)
    rng = np.random.default_rng(seed)
    i, j = (0, 1) if same else (0, 5)
    truth = _two_bodies(rng, 700, noise)
    truth[start - before:start + after] = np.nan                 # every marker hidden: no other reading either
    span = (start, start + length - 1)
    xyz = truth.copy()
    xyz[span[0]:span[1] + 1, [i, j]] = xyz[span[0]:span[1] + 1, [j, i]]
    found = exchanges(xyz, CHAIN)
    assert [(d["cols"], d["span"]) for d in found] == [((i, j), (start + after, span[1]))]
    a, b = found[0]["span"]
    xyz[a:b + 1, [i, j]] = xyz[a:b + 1, [j, i]]
    np.testing.assert_array_equal(xyz, truth)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), noise=st.floats(0.1, 1.5), n_gaps=st.integers(0, 12))
def test_gaps_in_smooth_motion_read_as_no_exchange(seed, noise, n_gaps):
    rng = np.random.default_rng(seed)
    xyz = _two_bodies(rng, 700, noise)
    for _ in range(n_gaps):                                  # gaps of 1-40 frames anywhere, in any marker
        a = int(rng.integers(0, 680))
        xyz[a:a + int(rng.integers(1, 41)), int(rng.integers(0, 7))] = np.nan
    assert exchanges(xyz, CHAIN) == []
    assert detect(xyz, CHAIN, noise, xyz.size) == []


def test_fit_leaves_out_a_swap_that_began_in_a_gap():
    rng = np.random.default_rng(5)
    model = Model.from_dict(tomllib.loads(MODEL))
    xyz = _swapped_in_gap(_two_bodies(rng, 600, 0.5), 0, 1, (200, 319), 4, 6)
    trial = Trial.from_array(xyz, CHAIN.labels, 100.0)
    screened, found = screen(model, trial)
    assert [(w["markers"], w["frames"]) for w in found] == [(["A1", "A2"], [200, 319])]
    assert np.isnan(screened.select(["A1", "A2"]).as_array()[200:320]).all()


def test_diagnose_names_a_thigh_shank_swap_that_began_in_a_gap(tmp_path):
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=900, noise_mm=0.5, seed=11)
    i, j = sim.trial.index("RTHI"), sim.trial.index("RTIB")
    xyz = _swapped_in_gap(sim.trial.as_array(), i, j, (400, 599), 5, 8)
    assert_swap_named_first(model, sim, xyz, tmp_path, {"RTHI", "RTIB"}, [400, 599])
