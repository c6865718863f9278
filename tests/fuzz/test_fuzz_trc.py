"""Malformed TRC files, made from a valid one: cut at every section, header fields that disagree with the data,
bad cells (inf, 1e30, text), rows out of order, encodings and binary content, reserved and duplicated names.

Each goes through ``identcheck fit`` and must end in exit 2 with the file and the offending line, column,
marker or field named on stderr; no traceback, no exit 3, the file unchanged (the ``run`` fixture)."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from fuzz_support import FUZZ, LEG

FIRST_ROW_LINE = 7          # lines 1-5 header, 6 blank (as write_trc writes it), data from line 7
N_ROWS = 200


def _lines(corpus) -> list[str]:
    return (corpus / "leg.trc").read_text().split("\n")


def _write(tmp_path, text, name="variant.trc"):
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return path


def _refused(run, path, *words):
    """fit on `path` exits 2 naming the file and every one of `words`."""
    res = run(["fit", LEG, path, "--json"])
    assert res.code == 2 and res.out == "", res.err
    assert res.names(path, *words), res.err
    return res


@FUZZ
@given(kept=st.integers(0, FIRST_ROW_LINE + N_ROWS - 3))
def test_a_file_cut_after_any_line_is_named(run, corpus, tmp_path, kept):
    """Cut after `kept` whole lines: an empty file, a header cut short (naming how many lines), no data rows,
    or fewer rows than line 3's NumFrames (naming line 3)."""
    path = _write(tmp_path, "".join(line + "\n" for line in _lines(corpus)[:kept]))
    words = (["empty file"] if kept == 0 else ["truncated header", f"only {kept} line"] if kept < 5 else
             ["no data rows", "line 6"] if kept < FIRST_ROW_LINE else ["line 3", "NumFrames = 200", "truncated"])
    _refused(run, path, *words)


@FUZZ
@given(line=st.integers(0, FIRST_ROW_LINE + N_ROWS - 3), cut=st.floats(0.05, 0.95))
def test_a_file_cut_inside_any_line_but_the_last_is_named(run, corpus, tmp_path, line, cut):
    """Cut inside line `line` (the last row excepted, which a writer stopped mid-way may leave and which is
    left out with a warning): the header or the NumFrames it announced no longer holds."""
    lines = _lines(corpus)
    head = "".join(x + "\n" for x in lines[:line])
    if not lines[line]:
        return
    path = _write(tmp_path, head + lines[line][:max(1, int(len(lines[line]) * cut))])
    res = run(["fit", LEG, path, "--json"])
    assert res.code == 2 and res.names(path), res.err
    assert "line" in res.err or "empty" in res.err, res.err


MARKERS = ("LASI", "RASI", "SACR", "RGT", "RTHI", "RKNE", "RTIB", "RANK", "RHEE", "RTOE")


@pytest.mark.parametrize("bad", ["inf", "-inf", "1e30", "-3e7", "1e308", "abc", "1,5", "--2", "0x10"])
@settings(FUZZ, max_examples=2)
@given(row=st.integers(0, N_ROWS - 1), marker=st.integers(0, len(MARKERS) - 1), axis=st.integers(0, 2))
def test_a_bad_cell_is_named_by_its_line_and_marker(run, corpus, tmp_path, bad, row, marker, axis):
    """One cell replaced by something that is not a coordinate (infinite, 1e30 or 30 km away, text): exit 2
    naming the line and the marker (a 1e30 sentinel used to leave no frame with a valid pose, unnamed)."""
    lines = _lines(corpus)
    cells = lines[FIRST_ROW_LINE - 1 + row].split("\t")
    cells[2 + 3 * marker + axis] = bad
    lines[FIRST_ROW_LINE - 1 + row] = "\t".join(cells)
    path = _write(tmp_path, "\n".join(lines))
    _refused(run, path, f"line {FIRST_ROW_LINE + row}", repr(MARKERS[marker]))


@pytest.mark.parametrize("line, old, new, words", [
    (3, "\t200\t10\tmm\t", "\t260\t10\tmm\t", ["line 3", "NumFrames = 260"]),
    (3, "\t200\t10\tmm\t", "\t200\t10\tinch\t", ["line 3", "Units", "'inch'"]),
    (3, "\t200\t10\tmm\t", "\t200\t10\tm\t", ["line 3", "Units says m", "coordinates are in mm"]),
    (3, "100\t100\t200", "0\t100\t200", ["line 3", "DataRate"]),
    (3, "100\t100\t200", "nan\t100\t200", ["line 3", "DataRate"]),
    (3, "100\t100\t200", "fast\t100\t200", ["line 3", "DataRate"]),
    (3, "\t200\t10\tmm\t", "\tmany\t10\tmm\t", ["line 3", "NumFrames", "'many'"]),
    (2, "\tUnits\t", "\tUnitz\t", ["line 2", "Units"]),
    (2, "DataRate\tCameraRate\t", "", ["line 2", "DataRate"]),
    (4, "\tRTHI\t", "\tRGT\t", ["line 4", "duplicate", "'RGT'"]),
    (4, "\tRTHI\t\t\t", "\t\tRTHI\t\t", ["line 4", "column"]),
    (5, None, None, ["line 5", "X/Y/Z line is missing"]),
])
def test_a_header_field_that_disagrees_is_named(run, corpus, tmp_path, line, old, new, words):
    """A header field changed against the rest of the file (frame count, units, rate, keys, names, the X/Y/Z
    line): exit 2 naming the line and the field."""
    lines = _lines(corpus)
    if old is None:                            # the line replaced by a data row (a writer that left it out)
        lines[line - 1] = lines[FIRST_ROW_LINE - 1]
    else:
        assert old in lines[line - 1], lines[line - 1]
        lines[line - 1] = lines[line - 1].replace(old, new, 1)
    _refused(run, _write(tmp_path, "\n".join(lines)), *words)


@FUZZ
@given(row=st.integers(0, N_ROWS - 2), column=st.sampled_from(["Frame#", "Time"]))
def test_rows_out_of_order_are_named(run, corpus, tmp_path, row, column):
    """Two neighbouring rows swapped (Frame# falls), or one row's Time set before the previous row's: exit 2
    naming the line and the column (before, frames going backwards passed silently)."""
    lines = _lines(corpus)
    k = FIRST_ROW_LINE - 1 + row
    if column == "Frame#":
        lines[k], lines[k + 1] = lines[k + 1], lines[k]
    else:
        cells = lines[k + 1].split("\t")
        cells[1] = f"{float(lines[k].split(chr(9))[1]) - 0.5:.6f}"
        lines[k + 1] = "\t".join(cells)
    _refused(run, _write(tmp_path, "\n".join(lines)), f"line {k + 2}", column)


def test_binary_content_and_other_encodings_are_named(run, corpus, tmp_path):
    """A C3D file or random bytes under a .trc name, and a marker name in Latin-1 (not UTF-8): exit 2 naming
    the file and, for the name, the model's marker the trial then lacks."""
    _refused(run, _write(tmp_path, (corpus / "leg.c3d").read_bytes(), "c3d_inside.trc"), "binary content")
    _refused(run, _write(tmp_path, bytes(range(256)) * 8, "noise.trc"), "binary content")
    raw = (corpus / "leg.trc").read_bytes().replace(b"\tRTHI\t", "\tRTH\u00c9\t".encode("latin-1"), 1)
    _refused(run, _write(tmp_path, raw, "latin1.trc"), "'RTHI'", "not in the trial")


def test_a_marker_named_like_a_virtual_one_is_refused(run, corpus, tmp_path):
    """A measured marker carrying the name fit gives a joint's centre (``hip_r.centre``), in the trial only
    or in the model too: exit 2 naming it (and, in the model, its key)."""
    trial = corpus / "leg.trc"
    renamed = _write(tmp_path, trial.read_text().replace("\tRTIB\t", "\thip_r.centre\t", 1), "virtual.trc")
    res = run(["fit", LEG, renamed, "--json"])
    assert res.code == 2 and res.names("'hip_r.centre'", "virtual marker"), res.err
    model = tmp_path / "virtual.toml"
    model.write_text(LEG.read_text().replace('"RTIB"', '"knee_r.axis0"'))
    for verb in ("fit", "plan"):
        argv = [verb, model, trial] if verb == "fit" else [verb, model, "--fast"]
        res = run(argv)
        assert res.code == 2 and res.names(model, "segments.shank_r.markers", "'knee_r.axis0'", "'knee_r'"), res.err
