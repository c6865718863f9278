"""Line numbers in a TRC's errors count the lines a text editor shows (ended by LF, CRLF or CR): a form feed or
another character ``str.splitlines`` also breaks at, inside the file, had shifted every later line number by one."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.io.trc import read_trc, write_trc

SEPARATORS = ["\f", "\v", "\x1c", "\x1d", "\x1e", "\x85", "\u2028"]


@settings(max_examples=20, deadline=None)
@given(n=st.integers(8, 60), data=st.data(), sep=st.sampled_from(SEPARATORS), ending=st.sampled_from(["\n", "\r\n"]))
def test_a_bad_cell_is_named_by_its_line_whatever_separators_come_before_it(tmp_path_factory, n, data, sep, ending):
    path = tmp_path_factory.mktemp("lines") / "t.trc"
    write_trc(path, np.random.default_rng(n).normal(0.0, 100.0, (n, 2, 3)), ["A", "B"], 100.0)
    lines = path.read_text().splitlines()
    bad = data.draw(st.integers(7, len(lines) - 1), label="bad line (0-based)")
    sep_at = data.draw(st.integers(5, bad - 1), label="line holding the separator (0-based)")
    lines[sep_at] += sep                       # after its last cell: the row still reads
    cells = lines[bad].split("\t")
    cells[3] = "oops"
    lines[bad] = "\t".join(cells)
    path.write_bytes(ending.join(lines).encode("utf-8") + ending.encode())
    with pytest.raises(InputError) as err:
        read_trc(path)
    assert f"line {bad + 1}" in str(err.value)
    assert f"line {bad + 2}" not in str(err.value)
