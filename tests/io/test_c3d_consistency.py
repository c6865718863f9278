"""A C3D file is checked against itself: the header's scale sign against POINT:SCALE (how coordinates are
stored), the frames read against the header's frame range and the bytes the file holds. A disagreement that
would change the numbers is an error naming the fields; a header that over-announces frames the parameters
and the file size agree on is a warning."""
from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.io.c3d import read_c3d, write_c3d

pytest.importorskip("ezc3d")


def _written(tmp_path, n_frames: int, n_markers: int, seed: int) -> tuple[bytearray, np.ndarray]:
    xyz = np.random.default_rng(seed).normal(size=(n_frames, n_markers, 3)) * 100
    path = tmp_path / "ok.c3d"
    write_c3d(path, xyz, [f"M{i}" for i in range(n_markers)], 100.0)
    return bytearray(path.read_bytes()), xyz


def _data_start(raw: bytes) -> int:
    return (struct.unpack("<H", raw[16:18])[0] - 1) * 512


@settings(max_examples=6, deadline=None)
@given(n_frames=st.integers(20, 120), n_markers=st.integers(1, 6), seed=st.integers(0, 1000))
def test_a_header_scale_of_the_other_sign_is_an_error_naming_point_scale(tmp_path_factory, n_frames, n_markers, seed):
    tmp = tmp_path_factory.mktemp("c3d")
    raw, _ = _written(tmp, n_frames, n_markers, seed)
    raw[12:16] = struct.pack("<f", -struct.unpack("<f", raw[12:16])[0])
    (tmp / "bad.c3d").write_bytes(raw)
    with pytest.raises(InputError, match="POINT:SCALE"):
        read_c3d(tmp / "bad.c3d")


@settings(max_examples=6, deadline=None)
@given(n_frames=st.integers(20, 120), n_markers=st.integers(1, 6), short=st.integers(1, 5), seed=st.integers(0, 1000))
def test_frames_past_the_headers_range_are_an_error(tmp_path_factory, n_frames, n_markers, short, seed):
    tmp = tmp_path_factory.mktemp("c3d")
    raw, _ = _written(tmp, n_frames, n_markers, seed)
    first, last = struct.unpack("<HH", raw[6:10])
    raw[6:10] = struct.pack("<HH", first, last - short)
    (tmp / "bad.c3d").write_bytes(raw)
    with pytest.raises(InputError, match="header's frame range"):
        read_c3d(tmp / "bad.c3d")


def test_a_header_that_over_announces_a_whole_file_is_a_warning_and_the_frames_are_read(tmp_path):
    raw, xyz = _written(tmp_path, 40, 3, 1)
    first, last = struct.unpack("<HH", raw[6:10])
    raw[6:10] = struct.pack("<HH", first, last + 3)
    (tmp_path / "over.c3d").write_bytes(raw)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = read_c3d(tmp_path / "over.c3d")
    assert data.xyz.shape == xyz.shape and np.allclose(data.xyz, xyz, atol=1e-3)
    assert any("announces" in str(w.message) for w in caught)


def test_a_file_cut_inside_its_data_is_an_error(tmp_path):
    raw, _ = _written(tmp_path, 60, 3, 2)
    cut = raw[:_data_start(raw) + 30 * 3 * 4 * 4 + 7]              # 30 whole frames and 7 bytes of the next
    (tmp_path / "cut.c3d").write_bytes(cut)
    with pytest.raises(InputError, match="truncated|not a readable"):
        read_c3d(tmp_path / "cut.c3d")


@settings(max_examples=4, deadline=None)
@given(n_frames=st.integers(32768, 65535), seed=st.integers(0, 2**16))
def test_more_than_32767_frames_read_back(tmp_path_factory, n_frames, seed):
    """POINT:FRAMES is a 16-bit integer that counts up to 65535: above 32767 it reads negative, and is still a
    count (the reader had refused every file it wrote of more than 32767 frames)."""
    xyz = np.random.default_rng(seed).normal(0, 100, (n_frames, 1, 3))
    path = tmp_path_factory.mktemp("long") / "long.c3d"
    write_c3d(path, xyz, ["M"], 100.0)
    back = read_c3d(path)
    assert back.xyz.shape == xyz.shape
    np.testing.assert_allclose(back.xyz[[0, -1]], xyz[[0, -1]], atol=1e-3)


def test_more_frames_than_a_c3d_counts_are_refused_before_writing(tmp_path):
    """ezc3d writes only the first 65535 frames of a longer trial, silently: the writer refuses instead."""
    path = tmp_path / "too_long.c3d"
    with pytest.raises(InputError, match="65536 frames; a C3D file counts at most 65535"):
        write_c3d(path, np.zeros((65536, 1, 3)), ["M"], 100.0)
    assert not path.exists()


@settings(max_examples=4, deadline=None)
@given(n_frames=st.integers(20, 80), n_markers=st.integers(1, 4), negative=st.booleans(), seed=st.integers(0, 1000))
def test_a_point_scale_of_zero_is_an_error_naming_it_not_markers_never_seen(tmp_path_factory, n_frames, n_markers,
                                                                            negative, seed):
    """POINT:SCALE 0 (or -0) makes the C3D library read every coordinate as 0: the file is refused by that field,
    not read as markers that are never visible (what the fit had said)."""
    import ezc3d

    tmp = tmp_path_factory.mktemp("c3d")
    _written(tmp, n_frames, n_markers, seed)
    c3d = ezc3d.c3d(str(tmp / "ok.c3d"))
    c3d["parameters"]["POINT"]["SCALE"]["value"] = np.array([-0.0 if negative else 0.0])
    c3d.write(str(tmp / "scale0.c3d"))
    with pytest.raises(InputError, match="POINT:SCALE is 0") as err:
        read_c3d(tmp / "scale0.c3d")
    assert "scale0.c3d" in str(err.value)
