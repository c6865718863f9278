"""A model segment whose markers lie farther apart than any body segment (a units field that scaled the numbers up)
is refused by :meth:`Trial.require_usable`, whatever part of the frames the two markers share; a declared
``length_mm`` lets a body truly that long through."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.errors import InputError
from identcheck.trial import LONGEST_SEGMENT_MM, Trial


def _trial(apart_mm: float, together: float, seed: int, n_frames: int = 200) -> Trial:
    """Three markers on one segment: A and B `apart_mm` apart, C near A; B is hidden in all but a share `together`
    of the frames, and A in some of the others (so that frames with one marker of the pair seen are many)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 50.0, (n_frames, 3))
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    xyz = np.stack([a, a + apart_mm * direction, a + 40.0 * np.roll(direction, 1)], axis=1)
    seen_b = rng.random(n_frames) < together
    seen_b[0] = True
    xyz[~seen_b, 1] = np.nan
    hide_a = ~seen_b & (rng.random(n_frames) < 0.5)
    xyz[hide_a, 0] = np.nan
    return Trial(xyz, ["A", "B", "C"], 100.0, source="span.trc")


@settings(max_examples=30, deadline=None)
@given(st.floats(1.05, 20.0), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_a_pair_farther_apart_than_a_segment_is_refused_however_little_it_is_seen_together(factor, together, seed):
    trial = _trial(factor * LONGEST_SEGMENT_MM, together, seed)
    where = {m: "thigh" for m in "ABC"}
    with pytest.raises(InputError) as info:
        trial.require_usable(["A", "B", "C"], where)
    msg = str(info.value)
    pair = msg.split("m (", 1)[1].split(", median", 1)[0]                     # B is far from both A and C
    assert "span.trc" in msg and "segment 'thigh'" in msg and "'B'" in pair and "units field" in msg, msg
    trial.require_usable(["A", "B", "C"], where, {"thigh": factor * LONGEST_SEGMENT_MM})      # declared: passes


@settings(max_examples=30, deadline=None)
@given(st.floats(10.0, 0.95 * LONGEST_SEGMENT_MM), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_segments_of_body_size_pass(apart_mm, together, seed):
    _trial(apart_mm, together, seed).require_usable(["A", "B", "C"], {m: "thigh" for m in "ABC"})


def test_markers_never_seen_together_say_nothing_of_the_span():
    xyz = np.full((10, 2, 3), np.nan)
    xyz[:5, 0] = 0.0
    xyz[5:, 1] = 10_000.0
    Trial(xyz, ["A", "B"], 100.0).require_usable(["A", "B"], {"A": "s", "B": "s"})
