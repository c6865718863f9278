"""Markers on one line do not pose their segment (:func:`identcheck.geometry.poses.off_line_mm`): the measure is the
RMS distance of the points from their best line, whatever the frame's pose, and zero on a line."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.geometry.poses import OFF_LINE_MM, off_line_mm, poses_segment


def _posed(local: np.ndarray, rng, n_frames: int = 20) -> np.ndarray:
    """`local` (m, 3) carried by random rigid poses: (F, m, 3)."""
    R = Rotation.random(n_frames, random_state=rng.integers(2**31)).as_matrix()
    t = rng.normal(0, 500, (n_frames, 3))
    return np.einsum("fij,mj->fmi", R, local) + t[:, None]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(3, 6), st.floats(0.0, 40.0))
def test_the_measure_is_the_rms_distance_from_the_line(seed, m, height):
    """Points spread along the x axis at -200..200 mm, each moved off it by a perpendicular offset whose offsets are
    centred and small beside the spread (so the x axis stays their best line): the measure is the offsets' RMS,
    in any pose; a multiple of the points scales it by the same factor."""
    rng = np.random.default_rng(seed)
    along = np.linspace(-200.0, 200.0, m)
    perp = rng.normal(size=(m, 2))
    perp -= perp.mean(axis=0)
    perp -= np.outer(along, along @ perp) / (along @ along)        # uncorrelated with the position along
    norm = np.sqrt(np.mean(np.sum(perp ** 2, axis=1)))
    perp = perp * (height / norm) if norm > 1e-9 else perp * 0.0
    local = np.column_stack([along, perp])
    pts = _posed(local, rng)
    expected = np.sqrt(np.mean(np.sum(perp ** 2, axis=1)))
    assert np.isclose(off_line_mm(pts), expected, rtol=1e-6, atol=1e-6)
    assert np.isclose(off_line_mm(2.5 * pts), 2.5 * expected, rtol=1e-6, atol=1e-6)
    assert poses_segment(pts) == (expected >= OFF_LINE_MM)


def test_fewer_than_three_points_or_no_full_frame():
    rng = np.random.default_rng(1)
    two = _posed(np.array([[0.0, 0, 0], [100.0, 0, 0]]), rng)
    assert off_line_mm(two) == 0.0 and not poses_segment(two)
    tri = _posed(np.array([[0.0, 0, 0], [100.0, 0, 0], [0, 80.0, 0]]), rng)
    tri[::2, 0] = np.nan
    tri[1::2, 1] = np.nan                                          # no frame sees all three
    assert off_line_mm(tri) == np.inf and poses_segment(tri)
