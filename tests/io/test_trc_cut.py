"""A TRC cut short or missing its X/Y/Z line: the coordinate-name line holding numbers is an error naming
line 5, and a file that ends inside its last row (no line end: the last number may be cut mid-digit) leaves
that row out with a warning naming the line; the rows before it read as from the whole file."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.io.trc import read_trc, write_trc


def _whole(tmp, n_frames: int, n_markers: int, seed: int):
    xyz = np.round(np.random.default_rng(seed).normal(size=(n_frames, n_markers, 3)) * 100, 3)
    write_trc(tmp / "ok.trc", xyz, [f"M{i}" for i in range(n_markers)], 100.0)
    return (tmp / "ok.trc").read_text(), xyz


@settings(max_examples=6, deadline=None)
@given(n_frames=st.integers(3, 40), n_markers=st.integers(1, 5), cut=st.integers(1, 4), seed=st.integers(0, 999))
def test_a_file_ending_inside_its_last_row_leaves_that_row_out_with_a_warning(tmp_path_factory, n_frames, n_markers,
                                                                             cut, seed):
    tmp = tmp_path_factory.mktemp("trc")
    text, xyz = _whole(tmp, n_frames, n_markers, seed)
    lines = text.rstrip("\n").split("\n")
    body = "\n".join(lines[:-1] + [lines[-1][:len(lines[-1]) - cut]])          # no line end, last number cut
    (tmp / "cut.trc").write_text(body)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = read_trc(tmp / "cut.trc")
    assert any(f"line {len(lines)}" in str(w.message) and "cut short" in str(w.message) for w in caught)
    assert data.xyz.shape[0] == n_frames - 1
    assert np.allclose(data.xyz, xyz[:-1], atol=1e-6, equal_nan=True)


def test_a_missing_xyz_line_is_an_error_naming_line_5(tmp_path):
    text, _ = _whole(tmp_path, 6, 2, 1)
    lines = text.split("\n")
    del lines[4:6]                         # the X/Y/Z line and the blank line after it (writers without one)
    (tmp_path / "noxyz.trc").write_text("\n".join(lines))
    with pytest.raises(InputError, match="line 5"):
        read_trc(tmp_path / "noxyz.trc")
