"""Trial and its TRC / C3D readers and writers: round trips, bad files, the real recordings."""
from __future__ import annotations

import hashlib
import shutil
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from identcheck.errors import InputError
from identcheck.io.c3d import MissingDependencyError
from identcheck.trial import Trial
from real_data import real_file, real_files

REAL_FILES = real_files()          # the repository's copies (examples/real) first, then the shared folder's

TRC_OK = (
    "PathFileType\t4\t(X/Y/Z)\tok.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "100.00\t100.00\t3\t2\tmm\t100.00\t1\t3\n"
    "Frame#\tTime\tA\t\t\tB\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    "\n"
    "1\t0.00\t1\t2\t3\t4\t5\t6\n"
    "2\t0.01\t1.5\t2.5\t3.5\t\t\t\n"
    "3\t0.02\t1\t2\t3\t4\t5\t6\n"
)


def sample_trial(n_frames=20, n_markers=4, seed=0, gaps=True) -> Trial:
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-2000, 2000, (n_frames, n_markers, 3))
    if gaps:
        xyz[3:7, 1] = np.nan
        xyz[-1, -1] = np.nan
    return Trial.from_array(xyz, [f"M{i}" for i in range(n_markers)], rate_hz=120.0)


def write(tmp_path, text, name="t.trc") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def assert_same(a: Trial, b: Trial, atol=1e-6):
    assert a.labels == b.labels
    assert a.rate_hz == pytest.approx(b.rate_hz)
    np.testing.assert_array_equal(np.isnan(a.xyz), np.isnan(b.xyz))
    np.testing.assert_allclose(a.xyz, b.xyz, atol=atol, rtol=0)


# ---------------------------------------------------------------------- Trial itself
def test_from_array_converts_metres_and_views():
    xyz = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    t = Trial.from_array(xyz, ["A", "B", "C"], rate_hz=50, units="m")
    assert (t.n_frames, t.n_markers) == (2, 3)
    np.testing.assert_array_equal(t.as_array(), xyz * 1000)
    np.testing.assert_array_equal(t.marker("B"), xyz[:, 1] * 1000)
    np.testing.assert_allclose(t.times, [0.0, 0.02])
    assert t.xyz.dtype == np.float64


def test_trial_is_not_modified_through_views_or_inputs():
    xyz = np.zeros((3, 1, 3))
    t = Trial.from_array(xyz, ["A"], 10.0)
    xyz[0, 0, 0] = 99.0
    assert t.xyz[0, 0, 0] == 0.0, "the trial must own a copy of its input"
    with pytest.raises(ValueError):
        t.xyz[0, 0, 0] = 1.0
    copy = t.as_array()
    copy[0, 0, 0] = 5.0
    assert t.xyz[0, 0, 0] == 0.0


def test_select_and_missing_markers_named():
    t = sample_trial()
    sub = t.select(["M2", "M0"])
    assert sub.labels == ("M2", "M0")
    np.testing.assert_array_equal(sub.xyz, t.xyz[:, [2, 0]])
    with pytest.raises(InputError, match="missing from the trial: RASI, LASI"):
        t.select(["M1", "RASI", "LASI"])
    with pytest.raises(InputError, match="no marker 'X' in the trial"):
        t.marker("X")


def test_gaps_mask():
    t = sample_trial()
    assert t.gaps.shape == (20, 4)
    assert t.gaps[3:7, 1].all() and t.gaps.sum() == 5


@pytest.mark.parametrize("kwargs, message", [
    (dict(xyz=np.zeros((4, 3)), labels=["A"] * 4, rate_hz=1), r"shape \(n_frames, n_markers, 3\)"),
    (dict(xyz=np.zeros((0, 2, 3)), labels=["A", "B"], rate_hz=1), "no frames"),
    (dict(xyz=np.zeros((2, 2, 3)), labels=["A"], rate_hz=1), "1 labels for 2 markers"),
    (dict(xyz=np.zeros((2, 2, 3)), labels=["A", "A"], rate_hz=1), "duplicate marker label 'A'"),
    (dict(xyz=np.zeros((2, 1, 3)), labels=["A"], rate_hz=0), "rate_hz must be a positive"),
    (dict(xyz=np.zeros((2, 1, 3)), labels=[""], rate_hz=1), "non-empty strings"),
    (dict(xyz=np.full((2, 1, 3), np.inf), labels=["A"], rate_hz=1), "infinite coordinate .* marker 'A'"),
    (dict(xyz=np.zeros((2, 1, 3)), labels=["A"], rate_hz=1, units="inch"), "unknown units 'inch'"),
    (dict(xyz=[["a"]], labels=["A"], rate_hz=1), "not a numeric array"),
])
def test_from_array_rejects_bad_input(kwargs, message):
    with pytest.raises(InputError, match=message):
        Trial.from_array(**kwargs)


def test_replace_keeps_the_rest():
    t = sample_trial()
    u = t.replace(xyz=t.as_array() + 1.0)
    assert u.labels == t.labels and u.rate_hz == t.rate_hz
    np.testing.assert_allclose(u.xyz, t.xyz + 1.0)


# ---------------------------------------------------------------------- round trips
def test_trc_round_trip_with_gaps(tmp_path):
    t = sample_trial()
    t.to_trc(tmp_path / "a.trc")
    assert_same(Trial.from_trc(tmp_path / "a.trc"), t)


def test_trc_written_in_opensim_layout(tmp_path):
    sample_trial(n_frames=3, n_markers=2).to_trc(tmp_path / "a.trc")
    lines = (tmp_path / "a.trc").read_text().split("\n")
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\ta.trc"
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    assert header["Units"] == "mm" and header["NumFrames"] == "3" and header["NumMarkers"] == "2"
    assert float(header["DataRate"]) == 120.0
    assert lines[3] == "Frame#\tTime\tM0\t\t\tM1\t\t"
    assert lines[4] == "\t\tX1\tY1\tZ1\tX2\tY2\tZ2"
    assert lines[6].split("\t")[:2] == ["1", "0.000000"]
    assert len(lines[6].split("\t")) == 2 + 3 * 2


def test_c3d_round_trip_with_gaps(tmp_path):
    t = sample_trial()
    # C3D stores 32-bit floats: compare data that float32 represents exactly
    t = t.replace(xyz=t.xyz.astype(np.float32).astype(np.float64))
    t.to_c3d(tmp_path / "a.c3d")
    assert_same(Trial.from_c3d(tmp_path / "a.c3d"), t)


@settings(max_examples=25, deadline=None)
@given(xyz=hnp.arrays(np.float64, hnp.array_shapes(min_dims=3, max_dims=3, min_side=1, max_side=6)
                      .map(lambda s: (s[0], s[1], 3)),
                      elements=st.one_of(st.floats(-1e4, 1e4, width=32), st.just(np.nan))),
       rate=st.sampled_from([50.0, 60.0, 100.0, 148.0, 250.0]),
       ext=st.sampled_from([".trc", ".c3d", ".TRC", ".C3D"]))
def test_round_trip_property(tmp_path_factory, xyz, rate, ext):
    """Written and read back, a trial is unchanged, except that a sample at exactly (0, 0, 0) comes back as a gap:
    in a file that is the exporters' placeholder for a missing sample (:func:`identcheck.trial.zeros_as_gaps`)."""
    xyz[np.isnan(xyz).any(axis=2)] = np.nan  # samples are whole or missing
    labels = [f"m{i}" for i in range(xyz.shape[1])]
    t = Trial.from_array(xyz, labels, rate)
    path = tmp_path_factory.mktemp("rt") / f"trial{ext}"
    t.to_file(path)
    expected = xyz.copy()
    expected[np.all(xyz == 0, axis=2)] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert_same(Trial.from_file(path), Trial.from_array(expected, labels, rate))


def test_zero_samples_in_a_file_are_gaps_with_a_warning(tmp_path):
    """A marker written as (0, 0, 0) in some frames is read as occluded there, and the warning names it and counts
    its frames; a coordinate of zero beside non-zero ones is a position."""
    xyz = np.arange(1.0, 1 + 5 * 2 * 3).reshape(5, 2, 3)
    xyz[1:3, 1] = 0.0
    xyz[4, 0, 0] = 0.0
    path = tmp_path / "zeros.trc"
    Trial.from_array(xyz, ["A", "B"], 100.0).to_file(path)
    with pytest.warns(UserWarning, match=r"2 sample\(s\) at exactly \(0, 0, 0\).*B \(2 frames\)"):
        t = Trial.from_file(path)
    assert np.isnan(t.xyz[1:3, 1]).all() and not np.isnan(t.xyz[[0, 3, 4], 1]).any()
    assert t.xyz[4, 0, 0] == 0.0


def test_from_file_unknown_extension(tmp_path):
    with pytest.raises(InputError, match=r"t\.csv: unknown trial file extension '\.csv'"):
        Trial.from_file(tmp_path / "t.csv")
    with pytest.raises(InputError, match="unknown trial file extension"):
        sample_trial().to_file(tmp_path / "t.txt")


# ---------------------------------------------------------------------- TRC reading
def test_trc_small_file(tmp_path):
    t = Trial.from_trc(write(tmp_path, TRC_OK))
    assert t.labels == ("A", "B") and t.rate_hz == 100.0 and t.n_frames == 3
    np.testing.assert_array_equal(t.xyz[0], [[1, 2, 3], [4, 5, 6]])
    assert np.isnan(t.xyz[1, 1]).all() and not np.isnan(t.xyz[1, 0]).any()


def test_trc_metres_become_mm(tmp_path):
    t = Trial.from_trc(write(tmp_path, TRC_OK.replace("\tmm\t", "\tm\t")))
    np.testing.assert_allclose(t.xyz[0], [[1000, 2000, 3000], [4000, 5000, 6000]])


def test_trc_crlf_line_endings(tmp_path):
    path = tmp_path / "crlf.trc"
    path.write_bytes(TRC_OK.replace("\n", "\r\n").encode())
    assert Trial.from_trc(path).n_frames == 3


@pytest.mark.parametrize("text, message", [
    ("", "empty file"),
    ("PathFileType\t4\n", r"truncated header: only 1 line"),
    (TRC_OK.replace("\tmm\t", "\tinch\t"), r"line 3: Units: unknown units 'inch' \(allowed: mm, cm, m\)"),
    (TRC_OK.replace("100.00\t100.00", "fast\tfast"), "line 3: DataRate = 'fast' is not a positive number"),
    (TRC_OK.replace("2.5\t3.5", "2.5\tabc"), r"line 8, column 5 \(marker 'A' Z\): 'abc' is not a finite number"),
    (TRC_OK.replace("1\t0.00\t1\t2\t3\t4\t5\t6", "1\t0.00\t1\t2\t3\t4\t5"),
     r"line 7: 7 columns, expected 8 \(Frame#, Time and X/Y/Z for 2 markers\)"),
    (TRC_OK.replace("3\t0.02\t1\t2\t3\t4\t5\t6", "3\t0.02\t1\t2\t3\t4\t5\t6\t7"), "line 9: 9 columns, expected 8"),
    (TRC_OK.replace("\tB\t", "\tA\t"), r"line 4: duplicate marker label 'A' \(columns 3 and 6\)"),
    (TRC_OK.replace("Frame#\tTime\tA\t\t\tB", "Frame#\tTime\tA\tB\t\t"),
     "line 4, column 4: 'B' is not in a marker-name column"),
    (TRC_OK.replace("\t3\t2\tmm", "\t5\t2\tmm"),
     r"NumFrames = 5 but the file has only 3 data rows \(lines 7-9\); .*truncated"),
    (TRC_OK.replace("DataRate\tCameraRate", "Rate\tCamRate").replace("Units", "U"), "is this a TRC file"),
    (TRC_OK.split("\n\n")[0] + "\n", "no data rows"),
    (TRC_OK.split("\n2\t")[0].replace("\t3\t2\tmm", "\t1\t2\tmm"),
     "the only data row, line 7, ends without a line end"),
])
def test_bad_trc_files(tmp_path, text, message):
    path = write(tmp_path, text, "bad.trc")
    with pytest.raises(InputError, match=message) as info:
        Trial.from_trc(path)
    assert str(path) in str(info.value)


def test_trc_lists_every_bad_cell_at_once(tmp_path):
    text = TRC_OK.replace("2.5\t3.5", "x\t3.5").replace("1\t2\t3\t4\t5\t6\n", "1\t2\t3\t4\t5\ty\n")
    with pytest.raises(InputError) as info:
        Trial.from_trc(write(tmp_path, text))
    assert len(info.value.problems) == 3
    assert "marker 'A' Y" in str(info.value) and "marker 'B' Z" in str(info.value)


def test_trc_more_rows_than_header_warns(tmp_path):
    path = write(tmp_path, TRC_OK.replace("\t3\t2\tmm", "\t2\t2\tmm"))
    with pytest.warns(UserWarning, match="NumFrames = 2 but the file has 3 data rows"):
        t = Trial.from_trc(path)
    assert t.n_frames == 3


@pytest.mark.parametrize("cell", ["", "x", "nan", "2.5"])
def test_a_frame_number_that_is_no_number_is_named_by_its_line(tmp_path, cell):
    """A Frame# cell that is empty or not a number: the warning names that row's line (it had named the first
    data row's line, whatever row held the bad cell)."""
    path = write(tmp_path, TRC_OK.replace("2\t0.01\t", f"{cell}\t0.01\t"))
    with pytest.warns(UserWarning, match=f"Frame# column is not a whole number at line 8 \\({cell!r}\\)"):
        t = Trial.from_trc(path)
    assert t.n_frames == 3


def test_a_frame_number_no_frame_can_have_is_named_not_wrapped(tmp_path):
    """A Frame# of 1e30 (rising, so in order) is named as no frame number, not cast to an integer no frame has."""
    path = write(tmp_path, TRC_OK.replace("3\t0.02\t", "1e30\t0.02\t"))
    with pytest.warns(UserWarning, match=r"Frame# column is not a whole number at line 9 \('1e30'\)"):
        t = Trial.from_trc(path)
    assert t.n_frames == 3


def test_trc_partial_sample_is_occluded_with_warning(tmp_path):
    path = write(tmp_path, TRC_OK.replace("1.5\t2.5\t3.5", "1.5\t\t3.5"))
    with pytest.warns(UserWarning, match="only some of X/Y/Z .* line 8, marker 'A'"):
        t = Trial.from_trc(path)
    assert np.isnan(t.xyz[1, 0]).all()


def test_trc_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.trc: file not found"):
        Trial.from_file(tmp_path / "nope.trc")


def test_binary_file_named_trc(tmp_path):
    path = tmp_path / "bin.trc"
    path.write_bytes(b"\x00\x01\x02" * 400)
    with pytest.raises(InputError, match="binary content"):
        Trial.from_trc(path)


# ---------------------------------------------------------------------- C3D reading
def test_c3d_garbage_empty_missing(tmp_path):
    (tmp_path / "g.c3d").write_text("hello, not a c3d file\n" * 40)
    with pytest.raises(InputError, match=r"g\.c3d: not a C3D file"):
        Trial.from_c3d(tmp_path / "g.c3d")
    (tmp_path / "e.c3d").write_bytes(b"")
    with pytest.raises(InputError, match=r"e\.c3d: empty file"):
        Trial.from_c3d(tmp_path / "e.c3d")
    with pytest.raises(InputError, match="file not found"):
        Trial.from_c3d(tmp_path / "missing.c3d")


def test_c3d_truncated(tmp_path):
    src = tmp_path / "full.c3d"
    sample_trial(n_frames=400, n_markers=10).to_c3d(src)
    raw = src.read_bytes()
    for cut, message in ((len(raw) // 2, "truncated file: the header announces 400 frames"),
                         (1000, "truncated|not a readable C3D file")):
        (tmp_path / "cut.c3d").write_bytes(raw[:cut])
        with pytest.raises(InputError, match=message):
            Trial.from_c3d(tmp_path / "cut.c3d")


def test_c3d_duplicate_labels_and_metres(tmp_path):
    import ezc3d
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("A", "B")
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    points = np.ones((4, 2, 5))
    points[:3] = 0.5
    c3d["data"]["points"] = points
    c3d.write(str(tmp_path / "m.c3d"))
    t = Trial.from_c3d(tmp_path / "m.c3d")
    np.testing.assert_allclose(t.xyz, 500.0)
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("A", "A")
    c3d.write(str(tmp_path / "dup.c3d"))
    with pytest.raises(InputError, match=r"dup\.c3d: POINT:LABELS: duplicate marker label 'A' \(points 0, 1\)"):
        Trial.from_c3d(tmp_path / "dup.c3d")


def test_missing_ezc3d_says_how_to_install(tmp_path, monkeypatch):
    sample_trial().to_c3d(tmp_path / "a.c3d")
    monkeypatch.setitem(sys.modules, "ezc3d", None)  # makes `import ezc3d` fail
    with pytest.raises(InputError, match=r"pip install identcheck\[c3d\]") as info:
        Trial.from_c3d(tmp_path / "a.c3d")
    assert isinstance(info.value, ImportError) and isinstance(info.value, MissingDependencyError)
    with pytest.raises(ImportError, match=r"pip install identcheck\[c3d\]"):
        sample_trial().to_c3d(tmp_path / "b.c3d")


# ---------------------------------------------------------------------- real recordings
@pytest.mark.skipif(not REAL_FILES, reason="no real data directory")
@pytest.mark.parametrize("path", REAL_FILES, ids=lambda p: p.name)
def test_real_files_load_unmodified(path):
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the real files must read without complaint
        t = Trial.from_file(path)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before
    assert t.n_frames > 100 and t.n_markers > 10
    assert all(t.labels) and len(set(t.labels)) == t.n_markers
    assert 50.0 <= t.rate_hz <= 1000.0
    # millimetres: a person in a lab spans ~100-5000 mm, not ~1-5 (m) or ~1e5
    finite = t.xyz[np.isfinite(t.xyz)]
    assert 500 < np.abs(finite).max() < 10_000
    assert np.isfinite(t.xyz).all(axis=2).any(axis=1).mean() > 0.5, "most frames see some marker"


@pytest.mark.skipif(not REAL_FILES, reason="no real data directory")
def test_real_file_facts():
    walk = Trial.from_file(real_file("opensim_subject01_walk1.trc"))
    assert (walk.n_frames, walk.n_markers, walk.rate_hz) == (151, 41, 60.0)
    assert walk.labels[:3] == ("R.ASIS", "L.ASIS", "V.Sacral")
    np.testing.assert_allclose(walk.marker("R.ASIS")[0], [617.24762, 1055.27502, 170.78198])
    vicon = Trial.from_file(real_file("opensim_walking2.c3d"))
    assert (vicon.n_frames, vicon.n_markers, vicon.rate_hz) == (1249, 44, 250.0)
    assert 0.3 < vicon.gaps.mean() < 0.7, "walking2 is known to have many gaps"
    if not real_file("biobuddy_right_hip.c3d").exists():
        return                                        # not shipped in the repository (3.7 MB): the shared folder's
    hip = Trial.from_file(real_file("biobuddy_right_hip.c3d"))
    assert (hip.n_frames, hip.n_markers, hip.rate_hz) == (1690, 73, 100.0)
    assert not hip.gaps.any()
    assert {"RASIS", "LASIS", "RTHI1", "RGT"} <= set(hip.labels)


@pytest.mark.skipif(not REAL_FILES, reason="no real data directory")
def test_real_trc_rewrite_round_trip(tmp_path):
    src = real_file("opensim_subject01_walk1.trc")
    t = Trial.from_file(src)
    t.to_trc(tmp_path / "copy.trc")
    assert_same(Trial.from_file(tmp_path / "copy.trc"), t)


@pytest.mark.skipif(not REAL_FILES, reason="no real data directory")
def test_real_c3d_with_gaps_round_trip(tmp_path):
    src = tmp_path / "walking2.c3d"
    shutil.copy(real_file("opensim_walking2.c3d"), src)  # work on a copy, never the original
    t = Trial.from_file(src)
    t.to_c3d(tmp_path / "copy.c3d")
    assert_same(Trial.from_file(tmp_path / "copy.c3d"), t, atol=1e-9)
