"""Frames as the capture software numbers them: TRC Frame#, C3D first frame, and --frames START:END."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.io.c3d import write_c3d
from identcheck.io.trc import write_trc
from identcheck.trial import Trial


@settings(max_examples=40, deadline=None)
@given(first=st.integers(0, 10 ** 5), n=st.integers(1, 300), a=st.integers(-50, 350), b=st.integers(-50, 350))
def test_frames_keeps_the_files_numbering(first, n, a, b):
    """A random file numbering and a random START:END: the sub-trial holds exactly the file's frames in
    [START, END] that exist, and its first frame keeps the file's number; an empty range is an error that
    gives the file's own range (a reversed one says so)."""
    xyz = np.arange(n * 3, dtype=float).reshape(n, 1, 3)
    t = Trial(xyz, ["M"], 100.0, "t", first_frame=first)
    start, end = first + a, first + b
    want = [f for f in range(first, first + n) if start <= f <= end]
    if not want:
        with pytest.raises(InputError, match=f"{first} to {first + n - 1}") as info:
            t.frames(f"{start}:{end}")
        assert ("END before START" in str(info.value)) == (end < start), str(info.value)
        for one_end in (f"{start}:", f":{end}"):                   # one end given: never "END before START"
            try:
                t.frames(one_end)
            except InputError as exc:
                assert "END before START" not in str(exc) and f"{first} to {first + n - 1}" in str(exc)
        return
    sub = t.frames(f"{start}:{end}")
    assert sub.first_frame == want[0] and sub.n_frames == len(want)
    assert np.array_equal(sub.as_array()[:, 0, 0], xyz[want[0] - first:want[-1] - first + 1, 0, 0])
    if end >= first:
        assert t.frames(f":{end}").first_frame == first
    if start <= first + n - 1:
        assert t.frames(f"{start}:").n_frames == sum(f >= start for f in range(first, first + n))


def test_trc_frame_column_is_the_files_numbering(tmp_path):
    """A TRC whose Frame# starts at 101: the trial's row 0 is frame 101, and the numbering survives
    selecting markers."""
    path = tmp_path / "t.trc"
    write_trc(path, np.zeros((5, 2, 3)) + 1.0, ["A", "B"], 100.0)
    lines = path.read_text().splitlines()
    head, rows = lines[:6], lines[6:]
    body = [str(int(r.split("\t")[0]) + 100) + "\t" + r.split("\t", 1)[1] for r in rows if r.strip()]
    path.write_text("\n".join(head + body) + "\n")
    t = Trial.from_trc(path)
    assert t.first_frame == 101 and t.select(["B"]).first_frame == 101
    assert t.frame_number(4) == 105


def test_bad_frames_argument_is_named():
    t = Trial(np.zeros((10, 1, 3)), ["M"], 100.0, "t", first_frame=1)
    with pytest.raises(InputError, match="START:END"):
        t.frames("a-b")


@settings(max_examples=15, deadline=None)
@given(first=st.integers(1, 30000), n=st.integers(2, 40))
def test_a_c3d_numbers_its_frames_as_its_header_does_and_as_its_trc_would(tmp_path_factory, first, n):
    """The C3D header's first frame is 1-based (what Nexus, QTM and Mokka show; ezc3d reads it less one): a C3D whose
    header says `first` numbers its rows from `first`, a write and read keep the numbering, and the same trial written
    as a TRC numbers its frames alike (a C3D had numbered them one less, so the same frame had two numbers)."""
    import ezc3d

    from identcheck.io.c3d import write_c3d

    folder = tmp_path_factory.mktemp("c3d")
    xyz = np.arange(n * 6, dtype=float).reshape(n, 2, 3) + 100.0
    write_c3d(folder / "t.c3d", xyz, ["A", "B"], 100.0, first_frame=first)
    with open(folder / "t.c3d", "rb") as f:
        head = f.read(10)
    assert int.from_bytes(head[6:8], "little") == first             # the header's word 4, as the spec reads it
    c3d = Trial.from_file(folder / "t.c3d")
    assert c3d.first_frame == first and c3d.frame_number(n - 1) == first + n - 1
    assert int(ezc3d.c3d(str(folder / "t.c3d"))["header"]["points"]["first_frame"]) == first - 1
    write_trc(folder / "t.trc", xyz, ["A", "B"], 100.0, first_frame=first)
    assert Trial.from_file(folder / "t.trc").first_frame == first
    c3d.to_file(folder / "again.c3d")
    assert Trial.from_file(folder / "again.c3d").first_frame == first


@settings(max_examples=15, deadline=None)
@given(first=st.integers(-3, 40), n=st.integers(2, 30), cut=st.integers(0, 5))
def test_a_trial_written_as_a_trc_keeps_the_numbering_it_was_read_with(tmp_path_factory, first, n, cut):
    """A TRC numbered from `first` (0 or below included), read, cut and written again, numbers its rows as the file
    did (a file numbered from 0 had been written from 1, so an export's frames sat one off the frames ``diagnose``
    names); a trial made from an array is written from 1; a C3D, which counts from 1, is written from 1 with a
    warning when the trial's numbering starts below."""
    folder = tmp_path_factory.mktemp("num")
    xyz = np.arange(n * 3, dtype=float).reshape(n, 1, 3) + 100.0
    write_trc(folder / "a.trc", xyz, ["M"], 100.0, first_frame=first)
    read = Trial.from_file(folder / "a.trc")
    assert read.first_frame == first
    part = read.frames(f"{first + min(cut, n - 1)}:")
    part.to_file(folder / "b.trc")
    again = Trial.from_file(folder / "b.trc")
    assert again.first_frame == first + min(cut, n - 1)
    assert np.array_equal(again.as_array(), part.as_array())
    Trial(xyz, ["M"], 100.0).to_file(folder / "c.trc")
    assert Trial.from_file(folder / "c.trc").first_frame == 1
    if first < 1:
        with pytest.warns(UserWarning, match="numbers its frames from 1"):
            read.to_file(folder / "d.c3d")
        assert Trial.from_file(folder / "d.c3d").first_frame == 1


@settings(max_examples=25, deadline=None)
@given(first=st.integers(0, 500), n=st.integers(3, 60), data=st.data())
def test_rows_a_trc_leaves_out_are_gaps_at_their_own_frame_numbers(tmp_path_factory, first, n, data):
    """A TRC whose Frame# skips numbers (rows dropped by an exporter) keeps the file's numbering: the frame numbered
    k holds the row numbered k, the frames left out are gaps, and a cut by --frames takes the file's frames. The
    rows had been renumbered one by one, so every frame after the first skip had another frame's number."""
    folder = tmp_path_factory.mktemp("skip")
    xyz = np.random.default_rng(n).normal(0.0, 100.0, (n, 2, 3))
    write_trc(folder / "all.trc", xyz, ["A", "B"], 100.0, first_frame=first)
    lines = (folder / "all.trc").read_text().splitlines()
    dropped = data.draw(st.sets(st.integers(1, n - 2), max_size=n - 3), label="dropped rows")
    kept = sorted(set(range(n)) - dropped)
    head = lines[:6]
    cells = head[2].split("\t")
    span = data.draw(st.booleans(), label="NumFrames counts the frames left out")
    cells[2] = str(kept[-1] - kept[0] + 1 if span else len(kept))   # NumFrames: the rows held, or the span
    head[2] = "\t".join(cells)
    (folder / "some.trc").write_text("\n".join(head + [lines[6 + k] for k in kept]) + "\n")
    if dropped:
        with pytest.warns(UserWarning, match="Frame# skips"):
            t = Trial.from_file(folder / "some.trc")
    else:
        t = Trial.from_file(folder / "some.trc")
    assert t.first_frame == first + kept[0] and t.n_frames == kept[-1] - kept[0] + 1
    got = t.as_array()
    for row in range(t.n_frames):
        k = kept[0] + row
        if k in kept:
            np.testing.assert_allclose(got[row], xyz[k], atol=1e-6)
        else:
            assert np.isnan(got[row]).all()
    last = t.frames(f"{first + kept[-1]}:")
    assert last.n_frames == 1 and np.allclose(last.as_array()[0], xyz[kept[-1]], atol=1e-6)


def test_a_frame_number_far_beyond_the_rows_is_refused_naming_its_line(tmp_path):
    """A Frame# that leaps past any plausible count of left-out frames is an error naming its line, not an array of
    gaps of that length."""
    path = tmp_path / "t.trc"
    write_trc(path, np.ones((10, 1, 3)), ["A"], 100.0)
    lines = path.read_text().splitlines()
    cells = lines[15].split("\t")                     # the last row (line 16), frame 10
    cells[0], cells[1] = "100000000", f"{(100000000 - 1) / 100.0:.6f}"     # its time agrees: only the count is off
    lines[15] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="line 16: Frame# jumps from 9 to 100000000"):
        Trial.from_file(path)


@settings(max_examples=15, deadline=None)
@given(n=st.integers(4, 40), cut=st.integers(0, 3), spike=st.booleans())
def test_an_arrays_rows_keep_their_written_numbers_when_cut_or_cleaned(tmp_path_factory, n, cut, spike):
    """A trial made from an array writes its row r as frame r + 1, whether written whole, cut with --frames (its
    own row numbers), or rebuilt without a gross spike: a cut had been written from its cut's number and a cleaned
    trial from 0, so one row had three numbers."""
    from identcheck.estimate.spikes import without_spikes

    folder = tmp_path_factory.mktemp("arr")
    xyz = np.cumsum(np.random.default_rng(n).normal(0.0, 1.0, (n, 2, 3)), axis=0) + 500.0
    if spike:
        xyz[n // 2, 0] += 5000.0
    t = Trial(xyz, ["A", "B"], 100.0)
    t.to_file(folder / "whole.trc")
    assert Trial.from_file(folder / "whole.trc").first_frame == 1
    part = t.frames(f"{cut}:")
    part.to_file(folder / "part.trc")
    assert Trial.from_file(folder / "part.trc").first_frame == cut + 1
    clean, _ = without_spikes(t)
    clean.to_file(folder / "clean.trc")
    assert Trial.from_file(folder / "clean.trc").first_frame == 1


@settings(max_examples=15, deadline=None)
@given(first=st.integers(65000, 70000), n=st.integers(2, 800))
def test_a_c3d_written_from_a_trial_numbered_past_its_16_bits_is_written_from_1_with_a_warning(
        tmp_path_factory, first, n):
    """A C3D header numbers frames at most to 65535: a trial whose frames run past it (a TRC numbered from 70 000) is
    written from 1 with a warning naming the file's numbers, where it had been written from the number less 65 536
    without one; a trial whose frames end within it keeps its numbering, silently."""
    import warnings as pywarnings

    folder = tmp_path_factory.mktemp("c3d16")
    write_trc(folder / "a.trc", np.random.default_rng(n).normal(0.0, 100.0, (n, 2, 3)), ["A", "B"], 100.0,
              first_frame=first)
    read = Trial.from_file(folder / "a.trc")
    with pywarnings.catch_warnings(record=True) as said:
        pywarnings.simplefilter("always")
        read.to_file(folder / "a.c3d")
    back = Trial.from_file(folder / "a.c3d")
    past = first + n - 1 > 65535
    assert back.first_frame == (1 if past else first)
    assert np.allclose(back.as_array(), read.as_array(), atol=1e-3)
    warned = [str(w.message) for w in said if "numbers its frames from 1" in str(w.message)]
    assert bool(warned) == past
    if past:
        assert f"{first} to {first + n - 1}" in warned[0] and "a.c3d" in warned[0]
    with pytest.raises(InputError, match="16-bit"):
        write_c3d(folder / "b.c3d", read.as_array(), ["A", "B"], 100.0, first_frame=65536 - n + 1)
