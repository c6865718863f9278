"""OpenSim TRC marker files: read and write.

Layout (tab-separated; line numbers from 1)::

    1  PathFileType  4  (X/Y/Z)  name.trc
    2  DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  ...
    3  60.00     60.00       151        41          mm     60.00         ...
    4  Frame#  Time  RASI  <tab><tab>  LASI  <tab><tab> ...
    5  <tab><tab>  X1  Y1  Z1  X2  Y2  Z2 ...
    6+ 1  0.000  x  y  z  x  y  z ...     (blank lines are skipped; empty cell = occluded)

Coordinates are converted to millimetres. The frame rate comes from ``DataRate`` (``CameraRate`` if
absent), and the Time column must step at it (within 1 %, or its last printed digit, over the file); Frame#
gives the file's numbering of its frames, and Frame# and Time must not go backwards.
"""
from __future__ import annotations

import math
import re
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from identcheck.errors import InputError, UnitsWarning
from identcheck.io.atomic import atomic_write
from identcheck.io.text import decode, plain, read_input

UNITS_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
"""Length units a trial file may use, with their factor to millimetres."""

_MAX_LISTED = 10  # per kind of problem, so a broken file does not print thousands of lines

FARTHEST_MM = 1e6
"""No marker of a capture is a kilometre from the origin: a coordinate beyond that is a sentinel, a corrupt
sample or wrong units (1e30 as "missing"), never a position, and one such sample wrecks every pose of its
frame (and float64 precision with it). A 100 m offset of the whole volume stays well inside."""


class MarkerData(NamedTuple):
    """What a reader returns (shared by the TRC and C3D readers).

    Attributes
    ----------
    xyz : numpy.ndarray
        Marker positions, shape (n_frames, n_markers, 3), float64, mm, NaN = occluded.
    labels : tuple of str
    rate_hz : float
    first_frame : int
    """

    xyz: np.ndarray
    labels: tuple
    rate_hz: float
    first_frame: int = 0
    """The file's own number of its first frame (TRC: the first row's Frame#; C3D: the header's first frame, 1-based,
    as Nexus, QTM and Mokka show it; ezc3d reads it less one): row i is the file's frame ``first_frame + i``."""


MAX_CELL_CHARS = 64
"""Longest cell of a data row: a number printed with every digit of a double takes about 25 characters. A longer
cell is no number, and a table of cells sized by the longest would take that size for every cell."""


def read_bytes(path: Path) -> bytes:
    """The bytes of a marker file (:func:`identcheck.io.text.read_input`: missing, directory, device, ...)."""
    return read_input(path, "marker file")


def unit_factor(units: str, where: str, problems: list[str]) -> float:
    """Factor from `units` to mm; appends a problem (naming `where`) if unknown."""
    key = str(units).strip().lower()
    if key in UNITS_TO_MM:
        return UNITS_TO_MM[key]
    problems.append(f"{where}: unknown units {units!r} (allowed: {', '.join(UNITS_TO_MM)})")
    return 1.0


def duplicates(labels) -> dict[str, list[int]]:
    """Labels that occur more than once, with the 0-based positions where they occur."""
    where: dict[str, list[int]] = {}
    for i, lab in enumerate(labels):
        where.setdefault(lab, []).append(i)
    return {lab: idx for lab, idx in where.items() if len(idx) > 1}


BODY_SPAN_MM = (10.0, 1e5)
"""What the markers of one frame may span (the median over frames of their bounding box's diagonal), in mm:
a capture holds a body, not a point and not a kilometre. Outside it the units field is wrong: millimetres
labelled m (a span of kilometres) are refused; metres labelled mm (a span of a few "millimetres") are warned
about, since a small rig could span that little."""


LARGE_SPAN_MM = 5_000.0
"""A span of the markers of one frame that is suspicious (warned about): when the units field scaled the numbers up,
the file's markers (mm labelled cm read as a leg 10 m long, a body 20 m tall); in the file's own mm, the model's
markers only (:func:`scaled_up_suspected`: a file may hold several subjects, or props, across the volume)."""

READ_TOO_LARGE = "more than one capture volume holds"
"""Words of the reader's question about a span its units field made too large (:func:`units_problem`)."""
MODEL_TOO_LARGE = "more than a body spans"
"""Words of the question about a model's markers spanning too much (:func:`scaled_up_suspected`): not asked again
where the reader asked already (:func:`identcheck.api._one_units_question`)."""


def units_problem(xyz: np.ndarray, factor: float, where: str) -> tuple[str, bool]:
    """Whether the file's units field (at `where`, read as `factor` to mm) contradicts its coordinates `xyz` (mm,
    as converted): the message and whether it is an error (else a warning); ('', False) when they agree or there
    is too little to tell (no frame with three markers seen)."""
    span = frame_span(xyz)
    if span is None:
        return "", False
    name = next((k for k, v in UNITS_TO_MM.items() if v == factor), "?")
    low, high = BODY_SPAN_MM
    if span > high and factor > 1.0:
        return (f"{where} says {name}, but then the markers of a frame span {span / 1e6:.3g} km (median over "
                "frames): the coordinates are in mm; fix the units field"), True
    if span > LARGE_SPAN_MM and factor > 1.0:
        return (f"{where} says {name}, but then the markers of a frame span {span / 1e3:.3g} m (median over "
                f"frames), {READ_TOO_LARGE}: are the coordinates in mm (or in a unit smaller than "
                f"{name})?"), False
    if span < low and factor == 1.0:
        return (f"{where} says {name}, but the markers of a frame span only {span:.3g} mm (median over frames): are "
                "the coordinates in metres?"), False
    return "", False


def frame_span(xyz: np.ndarray) -> float | None:
    """What the markers of one frame span: the median over the frames with three markers seen of their bounding
    box's diagonal (units of `xyz`); None when no frame has three."""
    seen = np.isfinite(xyz).all(axis=2)
    rows = np.flatnonzero(seen.sum(axis=1) >= 3)
    if not len(rows):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        box = np.nanmax(xyz[rows], axis=1) - np.nanmin(xyz[rows], axis=1)
    return float(np.median(np.linalg.norm(box, axis=1)))


SMALL_SPAN_MM = 250.0
"""A frame span (mm) below which the trial may be centimetres labelled mm (:func:`centimetres_suspected`): a lower
limb in cm spans about 100 "mm" and a whole body 200, where in mm a knee alone (two thigh markers and one on the
shank) spans 300 and a leg 1 000. A hand or a small animal can span that little in mm, so it is said as a question."""


def centimetres_suspected(xyz: np.ndarray, source: str) -> str:
    """A warning when the markers of a frame (`xyz`, mm as read) span less than :data:`SMALL_SPAN_MM` (but not so
    little that the readers already asked about metres): centimetres in a file that says mm make every distance
    reported ten times too small, and nothing else in a fit shows it. '' otherwise."""
    span = frame_span(xyz)
    if span is None or not BODY_SPAN_MM[0] <= span < SMALL_SPAN_MM:
        return ""
    return (f"{source}: the markers of a frame span only {span:.0f} mm (median over frames): a body part that small, "
            "or coordinates ten times too small for the units they are read in (centimetres in a file that says mm)? "
            "Then every distance here is ten times too small: fix the units (a file's POINT:UNITS or Units field, an "
            "array's units)")


def scaled_up_suspected(xyz: np.ndarray, source: str) -> str:
    """A warning when the markers of a model (`xyz`, mm as read: the model's markers only, one subject, where a file
    may hold several) span more than :data:`LARGE_SPAN_MM` in one frame (the median over frames): no body a model
    describes spans that much, and coordinates ten times too large for their units (a scale factor off, or a units
    field that says a smaller unit than the numbers are in) make every distance reported ten times too large, which
    nothing else in a fit shows. '' otherwise. (Files whose units field scaled their numbers up are warned about when
    read, :func:`units_problem`.)"""
    span = frame_span(xyz)
    if span is None or not LARGE_SPAN_MM < span <= BODY_SPAN_MM[1]:
        return ""
    return (f"{source}: the model's markers span {span / 1e3:.3g} m in a frame (median over frames), "
            f"{MODEL_TOO_LARGE}: coordinates ten times too large for the units they are read in (a scale factor off, "
            "or a units field naming a smaller unit than the numbers are in)? Then every distance here is ten times "
            "too large: fix the units (a file's POINT:UNITS or Units field, or its scale)")


def check_units(xyz: np.ndarray, factor: float, where: str, src: str, stacklevel: int = 4) -> None:
    """:func:`units_problem` acted on, for both readers: an InputError for a contradiction, a warning for a
    suspicion, nothing when the units field and the coordinates agree."""
    units, error = units_problem(xyz, factor, where)
    if error:
        raise InputError([units], source=src)
    if units:
        warnings.warn(f"{src}: {units}", UnitsWarning, stacklevel=stacklevel)


def far_samples(xyz: np.ndarray) -> np.ndarray:
    """(row, marker) of every sample of `xyz` (n_frames, n_markers, 3), mm, with a coordinate beyond
    :data:`FARTHEST_MM` (infinite ones included), in row order: the one test the readers and
    :class:`~identcheck.trial.Trial` apply."""
    with np.errstate(invalid="ignore"):
        return np.argwhere((np.abs(xyz) > FARTHEST_MM).any(axis=2))


def _capped(items: list[str], what: str) -> list[str]:
    if len(items) <= _MAX_LISTED:
        return items
    return items[:_MAX_LISTED] + [f"... and {len(items) - _MAX_LISTED} more {what}"]


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _cells(line: str) -> list[str]:
    """Tab-separated cells, stripped, without trailing empty cells."""
    cells = [c.strip() for c in line.split("\t")]
    while cells and not cells[-1]:
        cells.pop()
    return cells


# ---------------------------------------------------------------------- reading
def _lines(text: str) -> list[str]:
    """The file's lines, ended by LF, CRLF or CR alone: a form feed, vertical tab or other separator
    ``str.splitlines`` also breaks at is part of a line (it had shifted every later line number by one)."""
    lines = re.split(r"\r\n|\r|\n", text)
    return lines[:-1] if lines and lines[-1] == "" else lines


def read_trc(path) -> MarkerData:
    """Read an OpenSim TRC file.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    MarkerData
        ``xyz`` shape (n_frames, n_markers, 3) in mm (converted from the file's ``Units``),
        NaN where a cell is empty; ``labels`` from line 4; ``rate_hz`` from ``DataRate``.

    Raises
    ------
    InputError
        Missing or empty file, incomplete header, unknown units, missing / misplaced /
        duplicated marker names, rows with the wrong number of columns, non-numeric cells
        (naming line, column and marker), fewer data rows than ``NumFrames`` says.
        Every problem is listed at once.

    Warns
    -----
    UserWarning
        More data rows than ``NumFrames``, ``NumMarkers`` disagreeing with the names, or a
        sample with only some of its X/Y/Z cells filled (the sample is treated as occluded).
    """
    path = Path(path)
    src = str(path)
    raw = read_bytes(path)
    text = decode(raw, fallback="latin-1")
    if not text.strip():
        raise InputError(["empty file"], source=src)
    if "\x00" in text[:4096]:
        raise InputError(["binary content: not a text TRC file (a C3D file needs the .c3d extension)"],
                         source=src)
    lines = _lines(text)
    if len(lines) < 5:
        raise InputError([f"truncated header: only {len(lines)} line(s); a TRC file has 5 header "
                          "lines (PathFileType, keys, values, marker names, X/Y/Z) before the data"],
                         source=src)
    problems: list[str] = []
    xyz_line = [c for c in _cells(lines[4]) if c]
    if xyz_line and all(_is_number(c) for c in xyz_line):
        problems.append("line 5 holds numbers where the coordinate names (X1, Y1, Z1, ...) belong: the X/Y/Z "
                        "line is missing, so every row would be read one line off")
    rate_hz, factor, n_frames_hdr, n_markers_hdr = _parse_header(lines[1], lines[2], problems)
    labels = _parse_names(lines[3], problems)
    if n_markers_hdr is not None and labels and n_markers_hdr != len(labels):
        warnings.warn(f"{src}: line 3 says NumMarkers = {n_markers_hdr} but line 4 names "
                      f"{len(labels)} markers; using the names", UserWarning, stacklevel=3)
    width = 2 + 3 * len(labels)
    rows, linenos = [], []
    bad_width = []
    long_cells = []
    for i in range(5, len(lines)):
        if not lines[i].strip():
            continue
        cells = [c.strip() for c in lines[i].split("\t")]
        longest = max(cells, key=len)
        if len(longest) > MAX_CELL_CHARS:
            long_cells.append(f"line {i + 1}, column {cells.index(longest) + 1}: a cell of {len(longest):,} "
                              f"characters ({longest[:24]!r}...); a frame number, time or coordinate takes at most "
                              f"{MAX_CELL_CHARS}")
            continue
        if len(cells) > width and not any(cells[width:]):
            cells = cells[:width]
        if labels and len(cells) != width:
            n_cols = len(_cells(lines[i]))
            bad_width.append(f"line {i + 1}: {n_cols} columns, expected {width} (Frame#, Time and "
                             f"X/Y/Z for {len(labels)} markers)")
            continue
        rows.append(cells)
        linenos.append(i + 1)
    problems += _capped(long_cells, "cells too long to be a number")
    problems += _capped(bad_width, "rows with the wrong number of columns")
    cut_row = None
    if rows and linenos[-1] == len(lines) and not text.endswith(("\n", "\r")):
        cut_row = linenos[-1]
        warnings.warn(f"{src}: the file ends inside line {linenos[-1]} without a line end, so its last number may "
                      "be cut short; that row is left out", UserWarning, stacklevel=3)
        rows, linenos = rows[:-1], linenos[:-1]
        if n_frames_hdr == len(rows) + 1:        # the row left out was the last one NumFrames announces
            n_frames_hdr = len(rows)
    if not rows and not bad_width and cut_row is not None:
        problems.append(f"the only data row, line {cut_row}, ends without a line end: the file may be cut inside it, "
                        "so it is not read and no data rows remain (end the file with a line end if it is whole)")
    elif not rows and not bad_width:
        problems.append("no data rows after the header (data start on line 6)")
    if n_frames_hdr is not None and rows and not bad_width:
        if len(rows) < n_frames_hdr and _frame_span(rows) != n_frames_hdr:    # (frames left out are gaps)
            problems.append(f"line 3 says NumFrames = {n_frames_hdr} but the file has only {len(rows)} "
                            f"data rows (lines {linenos[0]}-{linenos[-1]}); the file looks truncated")
        elif len(rows) > n_frames_hdr:
            warnings.warn(f"{src}: line 3 says NumFrames = {n_frames_hdr} but the file has {len(rows)} "
                          "data rows; reading all of them", UserWarning, stacklevel=3)
    if problems:
        raise InputError(problems, source=src)
    values = _parse_numbers(np.array(rows, dtype=str)[:, 2:], linenos, labels, problems)
    if problems:
        raise InputError(problems, source=src)
    xyz = values.reshape(len(rows), len(labels), 3)
    _check_samples(xyz * factor, factor, rows, linenos, labels, src)
    clash = _rate_against_time(rows, linenos, rate_hz)
    if clash:
        raise InputError([clash], source=src)
    partial = np.isnan(xyz).any(axis=2) & ~np.isnan(xyz).all(axis=2)
    if partial.any():
        f, m = np.argwhere(partial)[0]
        warnings.warn(f"{src}: {int(partial.sum())} sample(s) have only some of X/Y/Z filled (first: "
                      f"line {linenos[f]}, marker {labels[m]!r}); treating them as occluded",
                      UserWarning, stacklevel=3)
        xyz[partial] = np.nan
    first, at = _frame_positions(rows, linenos, src)
    if at is not None:          # rows the file leaves out: gaps at their own frame numbers
        full = np.full((int(at[-1]) + 1,) + xyz.shape[1:], np.nan)
        full[at] = xyz
        xyz = full
    return MarkerData(xyz * factor, tuple(labels), rate_hz, first)


def _check_samples(mm: np.ndarray, factor: float, rows: list, linenos: list, labels, src: str) -> None:
    """The numbers of a well-formed file against what a capture can be: the units field against the markers'
    span, no sample beyond :data:`FARTHEST_MM`, rows in time order. Raises InputError naming the line, the
    columns and the marker (or warns, for a span that only suggests metres labelled mm)."""
    check_units(mm, factor, "line 3: Units", src, stacklevel=5)
    far = far_samples(mm)
    if len(far):
        listed = [f"line {linenos[f]}, columns {3 + 3 * m}-{5 + 3 * m} (marker {labels[m]!r}): "
                  f"{' '.join(rows[f][2 + 3 * m:5 + 3 * m])} is farther than {FARTHEST_MM / 1e6:g} km from the origin: "
                  "not a marker position (a sentinel for a missing sample? leave the cells empty)"
                  for f, m in far[:_MAX_LISTED]]
        more = [f"... and {len(far) - _MAX_LISTED} more samples that far"] if len(far) > _MAX_LISTED else []
        raise InputError(listed + more, source=src)
    order = _frame_order(rows, linenos)
    if order:
        raise InputError(order, source=src)


def _column(rows: list, col: int) -> np.ndarray | None:
    """Column `col` of the data rows as numbers, or None when some cell is not a number."""
    try:
        return np.array([float(r[col]) for r in rows])
    except (ValueError, IndexError):
        return None


RATE_TOLERANCE = 0.01
"""How far (relative) the rate the Time column steps at, over the whole file, may stand from ``DataRate``, beyond what
its printed digits can say (a time printed with few decimals rounds: at 60 Hz with three decimals each step reads
0.017 s or 0.016 s, and over a short file the last digit alone is more than 1 %)."""


def _rate_against_time(rows: list, linenos: list, rate_hz: float) -> str:
    """'' when the Time column (seconds) steps at ``DataRate`` per frame over the file, else what disagrees: every
    delay, velocity and frequency comes from the rate, and a DataRate of 1000 over a Time column stepping by 0.01 s had
    read a 37.4 ms delay as 3.74 ms, silently. The frames are counted by Frame# where it rises by whole numbers (a file
    with rows left out is not a wrong rate), else by rows; the tolerance is :data:`RATE_TOLERANCE` or the Time
    column's last printed digit over its span, whichever is larger. Not checked when Time is not numeric or does not
    rise."""
    times, frames = _column(rows, 1), _column(rows, 0)
    if times is None or len(rows) < 3 or not times[-1] > times[0]:
        return ""
    span_frames = _frame_span(rows)
    whole = span_frames is not None and np.all(np.abs(frames) < 1e9)   # (no capture reaches such frame numbers)
    steps = float(span_frames - 1) if whole else float(len(times) - 1)
    span = float(times[-1] - times[0])
    per_frame = span / steps
    decimals = max((len(r[1].split(".")[1]) if "." in r[1] and "e" not in r[1].lower() else 0) for r in rows[:50])
    tolerance = max(RATE_TOLERANCE, 10.0 ** -decimals / span)
    if abs(rate_hz * per_frame - 1.0) <= tolerance:
        return ""
    return (f"line 3: DataRate {rate_hz:g} Hz, but the Time column steps by {per_frame:.6g} s a frame (lines "
            f"{linenos[0]}-{linenos[-1]}), a rate of {1.0 / per_frame:.6g} Hz: which is right? Correct DataRate (or "
            "the Time column) so that they agree")


def _frame_order(rows: list, linenos: list) -> list[str]:
    """Frame# must rise and Time must not fall from row to row: rows out of order (a sort by another column,
    two takes pasted together) would be read as motion that never happened. The first such row is named;
    equal times are allowed (a high rate printed with few decimals repeats them)."""
    problems = []
    for col, name, bad in ((0, "Frame#", lambda step: step <= 0), (1, "Time", lambda step: step < 0)):
        values = _column(rows, col)
        if values is None or len(values) < 2:
            continue
        wrong = np.flatnonzero(bad(np.diff(values)))
        if len(wrong):
            k = int(wrong[0])
            problems.append(f"line {linenos[k + 1]}: {name} {rows[k + 1][col]} after {rows[k][col]} (line "
                            f"{linenos[k]}): {name} must {'rise' if col == 0 else 'not fall'} from row to row; the "
                            "rows are out of order")
    return problems


def _frame_span(rows: list) -> int | None:
    """How many frames the rows span by their Frame# (last − first + 1), or None when Frame# is not whole numbers
    rising: what a NumFrames that counts the frames an exporter left out gives."""
    frames = _column(rows, 0)
    if frames is None or not (np.all(np.abs(frames) < 2.0 ** 53) and np.all(frames == np.round(frames))
                              and np.all(np.diff(frames) > 0)):
        return None
    return int(frames[-1] - frames[0]) + 1


MAX_FILLED = 20
"""A TRC whose Frame# skips numbers is read with the frames it leaves out as gaps, up to this many frames per row the
file holds (a file of every 20th frame); beyond, it is refused naming the line of the largest skip."""


def _frame_positions(rows: list, linenos: list, src: str) -> tuple[int, np.ndarray | None]:
    """(the Frame# of the first data row, each row's position counted in frames from it, or None when the rows are
    consecutive). Frame numbers that skip (rows dropped by an exporter, a file of every other frame) keep their
    numbers: the frames left out become gaps, so that a frame's number, its time and ``--frames`` stay the file's.
    They had been renumbered by row, with a warning, and every frame after the first skip was named, cut and
    exported under another frame's number (its time with it). Frame numbers that are not whole numbers number the
    rows from 1, with a warning."""
    def number(cell: str) -> float:
        try:
            return float(cell)
        except ValueError:
            return float("nan")

    numbers = np.array([number(r[0]) if r else float("nan") for r in rows])
    with np.errstate(invalid="ignore"):        # no number, none a frame can have, or not a whole one
        bad = np.flatnonzero(~(np.abs(numbers) < 2.0 ** 53) | (numbers != np.floor(numbers)))
    if len(bad):
        cell = rows[bad[0]][0] if rows[bad[0]] else ""
        warnings.warn(f"{src}: the Frame# column is not a whole number at line {linenos[bad[0]]} ({cell!r}"
                      f"{f' and {len(bad) - 1} more rows' if len(bad) > 1 else ''}); frames are numbered from 1 by row",
                      UserWarning, stacklevel=4)
        return 1, None
    numbers = numbers.astype(np.int64)
    steps = np.diff(numbers)
    if not len(steps) or np.all(steps == 1):
        return int(numbers[0]), None
    at = numbers - numbers[0]
    k = int(np.argmax(steps))
    if at[-1] + 1 > MAX_FILLED * len(rows):
        raise InputError([f"line {linenos[k + 1]}: Frame# jumps from {numbers[k]} to {numbers[k + 1]}: the rows "
                          f"span {int(at[-1]) + 1:,} frames for {len(rows):,} rows, too few to be a recording with "
                          "frames left out; correct the Frame# column"], source=src)
    skips = np.flatnonzero(steps > 1)
    first = int(skips[0])
    warnings.warn(f"{src}: Frame# skips from {numbers[first]} to {numbers[first + 1]} at line {linenos[first + 1]}"
                  f"{f' and in {len(skips) - 1} more places' if len(skips) > 1 else ''}: the "
                  f"{int(at[-1]) + 1 - len(rows):,} frames the file leaves out are read as gaps, so that every frame "
                  "keeps its number and time", UserWarning, stacklevel=4)
    return int(numbers[0]), at


def _parse_header(keys_line: str, values_line: str, problems: list[str]):
    keys, values = _cells(keys_line), _cells(values_line)
    if len(values) != len(keys):
        problems.append(f"line 3: {len(values)} values for the {len(keys)} keys of line 2")
    header = dict(zip(keys, values))
    if "DataRate" not in header and "Units" not in header:
        problems.append("line 2: no DataRate or Units key; is this a TRC file? (line 2 must hold "
                        "DataRate, CameraRate, NumFrames, NumMarkers, Units, ...)")
        return 1.0, 1.0, None, None
    rate_key = "DataRate" if "DataRate" in header else "CameraRate"
    rate_hz = 1.0
    if rate_key not in header:
        problems.append("line 2: missing key DataRate (the frame rate in Hz)")
    else:
        try:
            rate_hz = float(header[rate_key]) if plain(header[rate_key]) else 0.0
            if not (math.isfinite(rate_hz) and rate_hz > 0):
                raise ValueError
        except ValueError:
            problems.append(f"line 3: {rate_key} = {header[rate_key]!r} is not a positive number of Hz")
            rate_hz = 1.0
    if "Units" not in header:
        problems.append("line 2: missing key Units (mm or m)")
        factor = 1.0
    else:
        factor = unit_factor(header["Units"], "line 3: Units", problems)
    counts = []
    for key in ("NumFrames", "NumMarkers"):
        value = header.get(key)
        if value is None:
            counts.append(None)
            continue
        try:
            if not plain(value):
                raise ValueError
            counts.append(int(value))
        except ValueError:
            problems.append(f"line 3: {key} = {value!r} is not a whole number")
            counts.append(None)
    return rate_hz, factor, counts[0], counts[1]


def _parse_names(line: str, problems: list[str]) -> list[str]:
    cells = _cells(line)
    if len(cells) < 3:
        problems.append("line 4: no marker names (expected Frame#, Time, then one name per X/Y/Z triple)")
        return []
    region = cells[2:]
    n = (len(region) + 2) // 3
    labels = []
    for k in range(n):
        name = region[3 * k]
        col = 3 + 3 * k  # 1-based column of this marker's name
        if not name:
            problems.append(f"line 4, column {col}: missing marker name (columns {col}-{col + 2})")
        for off in (1, 2):
            if 3 * k + off < len(region) and region[3 * k + off]:
                problems.append(f"line 4, column {col + off}: {region[3 * k + off]!r} is not in a "
                                "marker-name column (names go in every third column from column 3)")
        labels.append(name or f"<column {col}>")
    for lab, idx in duplicates(labels).items():
        cols = " and ".join(str(3 + 3 * i) for i in idx)
        problems.append(f"line 4: duplicate marker label {lab!r} (columns {cols})")
    return labels


def _not_plain(cells: np.ndarray) -> np.ndarray:
    """The cells that are no :func:`~identcheck.io.text.plain` number, (n_rows, n_cols); each cell is looked at
    only when the rows hold such characters at all (one test of their joined text)."""
    if plain("".join(cells.ravel().tolist())):
        return np.zeros(cells.shape, bool)
    return np.vectorize(lambda c: not plain(c), otypes=[bool])(cells)


def _parse_numbers(cells: np.ndarray, linenos: list[int], labels, problems) -> np.ndarray:
    """Cells (strings, shape (n_rows, 3 n_markers)) to float64, '' -> NaN; locate bad cells."""
    cells = np.where(cells == "", "nan", cells)
    try:
        values = cells.astype(np.float64)
    except ValueError:
        values = None
    odd = _not_plain(cells)
    if values is not None:
        bad = np.isinf(values) | odd
    else:
        values = np.full(cells.shape, np.nan)
        bad = np.zeros(cells.shape, bool)
        for (r, c), s in np.ndenumerate(cells):
            try:
                values[r, c] = float(s)
            except ValueError:
                bad[r, c] = True
        bad |= np.isinf(values) | odd
    found = []
    for r, c in np.argwhere(bad):
        what = "is not written in plain digits (0-9, '.', '-', 'e')" if odd[r, c] else "is not a finite number"
        found.append(f"line {linenos[r]}, column {c + 3} (marker {labels[c // 3]!r} {'XYZ'[c % 3]}): "
                     f"{str(cells[r, c])!r} {what}")
    problems += _capped(found, "non-numeric cells")
    return values


# ---------------------------------------------------------------------- writing
def write_trc(path, xyz: np.ndarray, labels, rate_hz: float, first_frame: int = 1) -> None:
    """Write marker trajectories as an OpenSim TRC file in millimetres.

    Parameters
    ----------
    path : str or os.PathLike
    xyz : array_like
        shape (n_frames, n_markers, 3), mm; NaN is written as an empty cell.
    labels : sequence of str
        Marker names (no tabs or line breaks).
    rate_hz : float
    first_frame : int
        Frame# of the first row, written as given (a file numbered from 0 is exported from 0: writing it from 1 had
        put ``--export-markers``' frames one number off the ones ``diagnose`` names). Time is ``(Frame# - 1) / rate``
        in a file numbered from 1 or later; one numbered from 0 or below starts at time 0.

    Raises
    ------
    InputError
        A label cannot be written in a TRC header.
    """
    path = Path(path)
    xyz = np.asarray(xyz, dtype=np.float64)
    n_frames, n_markers = xyz.shape[:2]
    bad = [lab for lab in labels if not lab or any(ch in lab for ch in "\t\r\n")]
    if bad:
        raise InputError([f"marker label {lab!r} cannot be written to a TRC file (empty, or has a "
                          "tab or line break)" for lab in bad], source=str(path))
    rate = f"{rate_hz:.6g}"
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n_frames}\t{n_markers}\tmm\t{rate}\t{int(first_frame)}\t{n_frames}",
        "Frame#\tTime\t" + "".join(f"{lab}\t\t\t" for lab in labels).rstrip("\t") + "\t\t",
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, n_markers + 1)),
        "",
    ]
    flat = xyz.reshape(n_frames, 3 * n_markers)
    cells = np.char.mod("%.8f", flat)
    cells[np.isnan(flat)] = ""
    first = int(first_frame)
    frames = np.char.mod("%d", np.arange(first, first + n_frames))
    times = np.char.mod("%.6f", (np.arange(n_frames) + max(first - 1, 0)) / rate_hz)
    body = ["\t".join((f, t, *row)) for f, t, row in zip(frames, times, cells)]
    atomic_write(path, "\n".join(head + body) + "\n")
