"""A TRC's DataRate against its Time column: every delay, velocity and frequency comes from the rate, so a DataRate
the Time column contradicts is refused, naming line 3 and both rates (a DataRate of 1000 over times stepping by
0.01 s had read a 37.4 ms delay as 3.74 ms, silently); times printed with few decimals, even over a short file, and
files with rows left out still agree."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.io.trc import read_trc, write_trc


def _trc(path, rate: float, n: int, seed: int):
    rng = np.random.default_rng(seed)
    write_trc(path, rng.normal(0.0, 100.0, (n, 2, 3)), ["A", "B"], rate)
    return path


def _with_data_rate(path, written: float, claimed: str):
    lines = path.read_text().splitlines(keepends=True)
    cells = lines[2].split("\t")
    assert float(cells[0]) == pytest.approx(written, rel=1e-4)      # (written with six significant digits)
    cells[0] = claimed
    lines[2] = "\t".join(cells)
    path.write_text("".join(lines))
    return path


@settings(max_examples=30, deadline=None)
@given(st.floats(10.0, 2000.0), st.floats(1.03, 20.0), st.booleans(), st.integers(3, 400), st.integers(0, 10**6))
def test_a_data_rate_the_time_column_contradicts_is_refused(tmp_path_factory, rate, factor, faster, n, seed):
    path = _trc(tmp_path_factory.mktemp("rate") / "t.trc", rate, n, seed)
    claimed = rate * factor if faster else rate / factor
    _with_data_rate(path, rate, f"{claimed:.6f}")
    with pytest.raises(InputError, match=r"line 3: DataRate .* but the Time column steps by .* a rate of"):
        read_trc(path)


@settings(max_examples=30, deadline=None)
@given(st.floats(10.0, 2000.0), st.integers(3, 400), st.integers(0, 10**6), st.integers(2, 6))
def test_times_rounded_to_few_decimals_agree_with_their_rate(tmp_path_factory, rate, n, seed, decimals):
    path = _trc(tmp_path_factory.mktemp("rate") / "t.trc", rate, n, seed)
    lines = path.read_text().splitlines(keepends=True)
    for i in range(6, len(lines)):
        cells = lines[i].split("\t")
        cells[1] = f"{float(cells[1]):.{decimals}f}"
        lines[i] = "\t".join(cells)
    path.write_text("".join(lines))
    if not round((n - 1) / rate, decimals) > 0:
        return                                  # every time printed as 0: no rate to read from the column
    assert read_trc(path).rate_hz == pytest.approx(rate, rel=1e-4)


@settings(max_examples=20, deadline=None)
@given(st.floats(10.0, 500.0), st.integers(20, 300), st.integers(0, 10**6))
def test_rows_left_out_are_no_wrong_rate(tmp_path_factory, rate, n, seed):
    """Frame# counts the frames: a file whose middle rows were left out (a warning says Frame# skips) keeps its
    rate."""
    path = _trc(tmp_path_factory.mktemp("rate") / "t.trc", rate, n, seed)
    lines = path.read_text().splitlines(keepends=True)
    body = lines[6:]
    kept = body[: n // 3] + body[2 * n // 3:]
    head = lines[:6]
    cells = head[2].split("\t")
    cells[2] = str(len(kept))
    head[2] = "\t".join(cells)
    path.write_text("".join(head + kept))
    with pytest.warns(UserWarning, match="Frame# skips"):
        assert read_trc(path).rate_hz == pytest.approx(rate, rel=1e-4)
