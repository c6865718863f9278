"""Label swaps on a segment of two markers (an anatomical layout: a lateral thigh marker and the epicondyle): their
one distance is the same exchanged, so neither the distances (:func:`detect`) nor the pose (:func:`flips`) can show
it. Each marker's position then continues from where the other was last seen: :func:`exchanges` finds the pair and
the span from that, across short gaps, and finds nothing in smooth motion. ``diagnose`` named such a swap (a
two-marker thigh's markers exchanged over 190 frames) as skin moving on the whole thigh."""
import tomllib

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.estimate.labels import detect, exchanges
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton
from tests.diagnose.test_two_marker_segment import MODEL   # a leg whose thigh carries two markers
from tests.swapped_trials import assert_swap_named_first



def _pair(rng, n_frames, noise, swap=None, gap=None):
    """Two markers 40–250 mm apart on a body turning smoothly (≤ 3 deg per frame) and moving up to 0.5 m/s;
    `swap` = (a, b): exchanged in rows a..b; `gap` = (a, b): both hidden in rows a..b."""
    local = np.array([[0.0, rng.uniform(20, 60), 0.0], [0.0, -rng.uniform(20, 190), rng.uniform(-20, 20)]])
    t = np.arange(n_frames) / 100.0
    freq, amp, phase = rng.uniform(0.2, 1.0, 3), rng.uniform(0.2, 0.8, 3), rng.uniform(0, 2 * np.pi, 3)
    R = Rotation.from_rotvec(amp * np.sin(2 * np.pi * freq * t[:, None] + phase)).as_matrix()
    pos = 500.0 * np.sin(rng.uniform(0.2, 1.0) * t)[:, None] * rng.normal(size=3) / np.sqrt(3)
    xyz = np.einsum("fij,mj->fmi", R, local) + pos[:, None] + rng.normal(0, noise, (n_frames, 2, 3))
    if swap:
        xyz[swap[0]:swap[1] + 1] = xyz[swap[0]:swap[1] + 1, ::-1]
    if gap:
        xyz[gap[0]:gap[1] + 1] = np.nan
    model = Model.from_dict(tomllib.loads('units = "mm"\n[segments.body]\nmarkers = ["A", "B"]\n'))
    return xyz, Skeleton.from_model(model)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), start=st.integers(20, 300), length=st.integers(5, 300),
       noise=st.floats(0.1, 1.5), gap=st.integers(0, 8))
def test_an_exchange_of_two_lone_markers_is_found_with_its_span(seed, start, length, noise, gap):
    rng = np.random.default_rng(seed)
    span = (start, start + length - 1)
    hidden = (start - gap, start - 1) if gap else None          # the exchange may begin inside a short gap
    xyz, chain = _pair(rng, 700, noise, span, hidden)
    assert detect(xyz, chain, noise, xyz.size) == []            # their one distance cannot show it
    found = exchanges(xyz, chain)
    assert [(d["cols"], d["span"]) for d in found] == [((0, 1), span)]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), noise=st.floats(0.1, 1.5))
def test_smooth_motion_of_two_lone_markers_shows_no_exchange(seed, noise):
    xyz, chain = _pair(np.random.default_rng(seed), 700, noise)
    assert exchanges(xyz, chain) == []


def test_diagnose_names_the_exchange_of_a_two_marker_thigh(tmp_path):
    path = tmp_path / "two_marker_thigh.toml"
    path.write_text(MODEL)
    model = Model.from_toml(path)
    sim = simulate(model, n_frames=900, noise_mm=0.5, seed=7)
    xyz = sim.trial.as_array()
    i, j = sim.trial.index("RTHI"), sim.trial.index("RKNE")
    xyz[300:451, [i, j]] = xyz[300:451, [j, i]]
    assert_swap_named_first(model, sim, xyz, tmp_path, {"RTHI", "RKNE"}, [300, 450])
