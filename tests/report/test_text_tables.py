"""The terminal tables: every cell under its header, whatever the widths, and text never read as a number."""
from __future__ import annotations

import re

from hypothesis import given, settings, strategies as st

from identcheck.report import text

NAME = st.text(alphabet=st.sampled_from("abcXYZ_019e.,- "), min_size=1, max_size=12).map(str.strip).filter(bool)
CELL = st.one_of(NAME, st.integers(-10**6, 10**6), st.floats(-1e6, 1e6, allow_nan=False), st.none())


def columns(rule: str) -> list:
    """(start, end) of each column from the rule of dashes under the header."""
    return [m.span() for m in re.finditer(r"-+", rule)]


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 6).flatmap(lambda n: st.tuples(
    st.lists(NAME, min_size=n, max_size=n, unique=True),
    st.lists(st.lists(CELL, min_size=n, max_size=n), min_size=1, max_size=6))),
    st.sampled_from(["", "   "]))
def test_every_cell_sits_under_its_header(table, indent):
    """Random headers and cells (names that look like numbers, ints, floats, None): each cell's text is read
    back from its column exactly as the table's rule places it, None as '-', floats at 2 decimals, text as
    given, and the header names line up with the same columns."""
    headers, rows = table
    lines = text.table(rows, headers, indent=indent)
    assert len(lines) == len(rows) + 2 and all(line.startswith(indent) for line in lines)
    spans = columns(lines[1][len(indent):])
    assert len(spans) == len(headers)
    body = [line[len(indent):] for line in lines]

    def read(line, k):
        a, b = spans[k]
        # a right-aligned cell may start left of its span only if the header is narrower: never here
        return line[a:b].strip()

    assert [read(body[0], k) for k in range(len(headers))] == headers
    for row, line in zip(rows, body[2:]):
        want = ["-" if v is None else format(v, ".2f") if isinstance(v, float) else str(v) for v in row]
        assert [read(line, k) for k in range(len(headers))] == want


def test_a_numeric_column_is_right_aligned_and_a_text_column_left_aligned():
    lines = text.table([["hip", 1.5], ["knee_long_name", 123.25]], ["joint", "d"])
    assert lines[2].startswith("hip ") and lines[2].endswith("  1.50") and lines[3].endswith("123.25")


def test_identify_text_puts_each_candidate_distance_under_its_marker():
    """identify's candidate table, from a result document: each distance under its marker's column."""
    doc = {"joints": {"knee_r": {
        "type": "revolute", "case": "revolute(2,1)", "n_samples": 5, "candidates": 2, "parameter_sets": 1,
        "unique": False, "rms_residual": 0.001,
        "marker_distances": {"1e3": 156.614, "RTH2": 82.83, "RTIB": 163.2},
        "alternatives": [{"marker_distances": {"1e3": 161.46, "RTH2": 85.391, "RTIB": 158.26}}]}}}
    out = text.identify_text(doc).splitlines()
    head, rule = out[2], out[3]
    spans = columns(rule)
    assert [head[a:b].strip() for a, b in spans] == ["candidate", "1e3", "RTH2", "RTIB"]
    assert [out[4][a:b].strip() for a, b in spans] == ["joint 0", "156.61", "82.83", "163.20"]
    assert [out[5][a:b].strip() for a, b in spans] == ["joint 1", "161.46", "85.39", "158.26"]


def test_long_lists_in_an_effects_place_are_cut_in_the_text_report():
    """A distortion may fit 53 fields: the text report shows the first few and how many more (the JSON has all); a
    short list, and a long frame list (left out), as before."""
    from identcheck.report.text import LIST_SHOWN, _where_text

    names = [f"field {i}" for i in range(20)]
    text = _where_text({"degree": 3, "fields": names})
    assert f"and {20 - LIST_SHOWN} more" in text and names[LIST_SHOWN - 1] in text and names[LIST_SHOWN] not in text
    assert _where_text({"joint": "hip", "functions": ["ωx³"]}) == "joint=hip, functions=['ωx³']"
    assert "frames" not in _where_text({"markers": ["A"], "frames": list(range(10))})
