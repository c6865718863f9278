"""Label swaps the distances cannot see: two markers placed alike relative to the rest of their segment (an
isosceles triangle's base, a pair mirror-symmetric about the other markers' plane) exchanged over a span. The
segment's pose turns by a half turn at both ends of the span; :func:`flips` finds the pair and the span from that,
and finds nothing in smooth motion. Exchanging such a pair of three markers where it is labelled right makes that half
turn, and is no swap (:func:`exchange_turns_over`); exchanging back a pair that was swapped does not."""
import tomllib

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.estimate.labels import detect, exchange_turns_over, flips, screen
from identcheck.io.model import Model
from identcheck.skeleton import Skeleton
from identcheck.trial import Trial

MODEL = """
units = "mm"
[segments.body]
markers = ["P", "Q1", "Q2", "S"]
[segments.other]
markers = ["O1", "O2", "O3"]
[joints.j]
type = "spherical"
parent = "body"
child = "other"
"""


def _trial(rng, n_frames, noise, four, swap=None):
    """Markers of a rigid body turning smoothly (≤ 3 deg per frame), Q1 and Q2 mirror images of each other about
    the plane of P, S and the body's long axis; `swap` = (a, b): Q1 and Q2 exchanged in rows a..b."""
    apex = rng.uniform(80, 200)
    half, depth = rng.uniform(30, 90), rng.uniform(-40, 40)
    local = {"P": [0.0, apex, 0.0], "Q1": [half, 0.0, depth], "Q2": [-half, 0.0, depth],
             "S": [0.0, -rng.uniform(60, 150), rng.uniform(-30, 30)] if four else [np.nan] * 3,
             "O1": [0.0, 300.0, 0.0], "O2": [40.0, 350.0, 10.0], "O3": [-30.0, 380.0, -20.0]}
    t = np.arange(n_frames) / 100.0
    freq, amp, phase = rng.uniform(0.2, 1.0, 3), rng.uniform(0.2, 0.8, 3), rng.uniform(0, 2 * np.pi, 3)
    rotvec = amp * np.sin(2 * np.pi * freq * t[:, None] + phase)           # ≤ 0.05 rad per frame
    R = Rotation.from_rotvec(rotvec).as_matrix()
    pos = 500.0 * np.sin(0.3 * t)[:, None] * np.array([1.0, 0.2, 0.0])
    labels = list(local)
    xyz = np.einsum("fij,mj->fmi", R, np.array([local[m] for m in labels])) + pos[:, None]
    xyz += rng.normal(0, noise, xyz.shape)
    if swap:
        a, b = swap
        i, j = labels.index("Q1"), labels.index("Q2")
        xyz[a:b + 1, [i, j]] = xyz[a:b + 1, [j, i]]
    if not four:
        k = labels.index("S")
        labels.pop(k)
        xyz = np.delete(xyz, k, axis=1)
    return Trial.from_array(xyz, labels, 100.0)


def _chain(four):
    text = MODEL if four else MODEL.replace('"P", "Q1", "Q2", "S"', '"P", "Q1", "Q2"')
    model = Model.from_dict(tomllib.loads(text))
    return model, Skeleton.from_model(model)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans(), st.floats(0.0, 1.0), st.sampled_from(["middle", "start", "end"]))
def test_a_swap_the_distances_cannot_see_is_found_by_the_flip(seed, four, noise, where):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 500))
    length = int(rng.integers(5, n // 3))
    a = {"middle": int(rng.integers(1, n - length - 1)), "start": 0, "end": n - length}[where]
    b = a + length - 1
    model, chain = _chain(four)
    trial = _trial(rng, n, noise, four, swap=(a, b))
    data = trial.select(chain.labels).as_array()
    assert detect(data, chain, max(noise, 0.3), data.size) == []         # the distances do not show it
    found = flips(data, chain)
    cols = tuple(sorted(chain.labels.index(m) for m in ("Q1", "Q2")))
    assert [(d["cols"], d["span"]) for d in found] == [(cols, (a, b))]
    screened, warnings = screen(model, trial)
    assert [w["markers"] for w in warnings] == [["Q1", "Q2"]] and warnings[0]["frames"] == [a, b]
    assert np.isnan(screened.select(["Q1", "Q2"]).as_array()[a:b + 1]).all()


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans(), st.floats(0.0, 2.0))
def test_smooth_motion_has_no_flip(seed, four, noise):
    rng = np.random.default_rng(seed)
    _, chain = _chain(four)
    trial = _trial(rng, int(rng.integers(50, 400)), noise, four)
    assert flips(trial.select(chain.labels).as_array(), chain) == []


def _span(rng, n):
    length = int(rng.integers(5, n // 3))
    a = int(rng.integers(1, n - length - 1))
    return a, a + length - 1


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 1.0), st.booleans())
def test_exchanging_a_mirror_pair_labelled_right_turns_the_segment_over(seed, noise, fitted_shape):
    """Three markers, two of them the base of an isosceles triangle: exchanged, they are the triangle turned by a
    half turn about its axis of symmetry. (With a fourth marker off that axis no rotation reaches the exchange, and
    the best pose need not turn far.)"""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 500))
    model, chain = _chain(False)
    data = _trial(rng, n, noise, False).select(chain.labels).as_array()
    cols = tuple(chain.labels.index(m) for m in ("Q1", "Q2"))
    assert exchange_turns_over(data, chain, cols, _span(rng, n), data[0] if fitted_shape else None)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans(), st.floats(0.0, 1.0), st.sampled_from(["mirror", "other", "across"]),
       st.booleans(), st.booleans())
def test_exchanging_back_a_swapped_pair_does_not(seed, four, noise, pair, fitted_shape, frame_off):
    """Any pair swapped over a span (the mirror pair, P with another marker of its segment, P with a marker of the
    other segment), exchanged back over that span or over one a frame longer (its segment then turns over at one end
    only), with the segments' shapes given or read from the data: exchanging it back restores the segment's own
    shape, and its pose turns across the span's ends only as the motion does, or at one end."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 500))
    model, chain = _chain(four)
    names = {"mirror": ("Q1", "Q2"), "other": ("P", "S" if four else "Q1"), "across": ("P", "O1")}[pair]
    a, b = _span(rng, n)
    data = _trial(rng, n, noise, four).select(chain.labels).as_array()
    cols = tuple(chain.labels.index(m) for m in names)
    local = data[0] if fitted_shape else None                   # row 0 is before the span: labelled right
    data[a:b + 1, list(cols)] = data[a:b + 1, list(cols[::-1])]
    assert not exchange_turns_over(data, chain, cols, (a, b + int(frame_off)), local)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.2, 1.0))
def test_markers_near_one_line_say_nothing(seed, noise):
    """Three markers within half a millimetre of one line do not pose their segment (their roll is noise, and a true
    swap exchanged back can seem to turn it over by chance), so the segment is not judged at all: not even an
    exchange of its two end markers, which turns the line end over end, is called a turn-over; the fit decides."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 400))
    model, chain = _chain(False)
    t = np.arange(n) / 100.0
    R = Rotation.from_rotvec(0.5 * np.sin(2 * np.pi * 0.5 * t[:, None] + rng.uniform(0, 6, 3))).as_matrix()
    local = np.array([[0.0, 120.0, 0.3], [0.0, 0.0, -0.3], [0.2, -90.0, 0.0],
                      [0.0, 300.0, 0.0], [40.0, 350.0, 10.0], [-30.0, 380.0, -20.0]])
    data = np.einsum("fij,mj->fmi", R, local) + rng.normal(0, noise, (n, 6, 3))
    assert not exchange_turns_over(data, chain, (0, 2), _span(rng, n))
